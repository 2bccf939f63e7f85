#!/usr/bin/env bash
# The one test command (README "Quick start"): installs what the tests need, then runs the format check,
# clippy with -D warnings, the API docs and the book, every test of the workspace (unit tests next to the
# code, end-to-end tests in tests/), and the 24-simulated-hour soak (tests/soak.rs) in release.
#
# It installs Debian's chromium (the dashboard's browser test drives it with playwright-core) when it is
# missing, the dashboard's npm packages from web/package-lock.json, the Foxglove test client's from
# tests/foxglove/package-lock.json, and the independent MCAP reader (the `mcap` Python packages pinned in
# tests/python/requirements.txt) into the venv target/py-mcap, and the `eclipse-zenoh` Python package (pinned in
# tests/python/requirements-zenoh.txt) into target/py-zenoh. Nothing downloads a browser of its own.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

# ---- load mode (PAVLOV_TEST_LOAD=N): N busy loops beside the whole run ---------------------------------
# The suite must pass on a machine that is busy with other work (issue 23): PAVLOV_TEST_LOAD=2 starts two
# busy loops before the first step and kills them when the script exits, however it exits. The load
# average is printed at the start and at the end.
LOAD_PIDS=()
load_average() { cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || uptime; }
stop_load() {
  local rc=$?
  if [ "${#LOAD_PIDS[@]}" -gt 0 ]; then
    printf '\n==> load mode: load average at the end: %s; stopping %s busy loops\n' \
      "$(load_average)" "${#LOAD_PIDS[@]}"
    kill "${LOAD_PIDS[@]}" 2>/dev/null || true
    wait "${LOAD_PIDS[@]}" 2>/dev/null || true
  fi
  exit "$rc"
}
if [ -n "${PAVLOV_TEST_LOAD:-}" ]; then
  case "$PAVLOV_TEST_LOAD" in
    '' | *[!0-9]*) echo "PAVLOV_TEST_LOAD must be a number of busy loops, not '$PAVLOV_TEST_LOAD'" >&2; exit 2 ;;
  esac
  trap stop_load EXIT
  trap 'exit 130' INT TERM
  for _ in $(seq 1 "$PAVLOV_TEST_LOAD"); do
    sh -c 'while :; do :; done' &
    LOAD_PIDS+=("$!")
  done
  step "load mode: $PAVLOV_TEST_LOAD busy loops beside the suite (pids ${LOAD_PIDS[*]}); load average at the start: $(load_average)"
fi
# ---- end of load mode ------------------------------------------------------------------------------------

if ! command -v chromium >/dev/null 2>&1 && [ ! -x /usr/bin/chromium ]; then
  step "installing Debian's chromium for the browser test"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

if [ -f web/package-lock.json ]; then
  step "installing the dashboard's npm packages (npm ci)"
  npm ci --prefix web --no-audit --no-fund --loglevel=error
  step "dashboard JavaScript unit tests (node --test)"
  npm test --prefix web
fi

step "installing the Foxglove test client's npm packages (npm ci)"
# tests/e2e/foxglove.rs connects with Foxglove's own client library (@foxglove/ws-protocol), pinned in
# tests/foxglove/package-lock.json; the test fails, saying so, when they are missing.
npm ci --prefix tests/foxglove --no-audit --no-fund --loglevel=error
PY_VENV="${CARGO_TARGET_DIR:-target}/py-mcap"
step "installing the independent MCAP reader (tests/python/requirements.txt) into $PY_VENV"
if ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
  # Debian splits venv's pip bootstrap into its own package.
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv >/dev/null
fi
[ -x "$PY_VENV/bin/python" ] || python3 -m venv "$PY_VENV"
"$PY_VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy --all-targets -- -D warnings (without and with the optional zenoh feature)"
cargo clippy --workspace --all-targets -- -D warnings
cargo clippy --workspace --all-targets --features pavlov-actors/zenoh -- -D warnings

# --- the documentation: API docs and the book (docs/) ----------------------------------------------------
# rustdoc with warnings as errors (broken intra-doc links, links to private items, stray HTML), then the
# mdBook book into target/book. mdBook comes from crates.io, pinned, without its default features (no local
# web server, file watcher or search index: a smaller build, about 2.5 min of CPU), and only when no mdbook
# of that version is on the PATH; it goes into its own folder beside the build, never into ~/.cargo/bin.
# The book's links, and those of README.md, ARCHITECTURE.md and web/PROTOCOL.md, are checked by
# tests/e2e/docs.rs in `cargo test` below.
step "cargo doc --no-deps with -D warnings (without and with the optional zenoh feature)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --features pavlov-actors/zenoh
MDBOOK_VERSION="0.4.52"
MDBOOK="mdbook"
if [ "$(mdbook --version 2>/dev/null)" != "mdbook v$MDBOOK_VERSION" ]; then
  MDBOOK_ROOT="${CARGO_TARGET_DIR:-target}/mdbook-$MDBOOK_VERSION"
  MDBOOK="$MDBOOK_ROOT/bin/mdbook"
  if [ ! -x "$MDBOOK" ]; then
    step "installing mdBook $MDBOOK_VERSION into $MDBOOK_ROOT (cargo install --locked --no-default-features)"
    time cargo install mdbook --locked --no-default-features --version "$MDBOOK_VERSION" --root "$MDBOOK_ROOT"
  fi
fi
step "mdbook build docs (into target/book)"
"$MDBOOK" build docs
# --- end of the documentation ----------------------------------------------------------------------------

step "cargo test (unit and end-to-end; with the zenoh feature, so the fleet test runs)"
cargo test --workspace --all-targets --features pavlov-actors/zenoh

# --- the Python loader (python/pavlov_recording.py) ------------------------------------------------------
# Its packages (python/requirements.txt: the mcap pins above plus pandas and numpy) go into the same venv;
# its test makes a fresh recording with the debug binary `cargo test` just built.
step "python/pavlov_recording.py against a fresh recording (python/requirements.txt into $PY_VENV; unittest)"
"$PY_VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r python/requirements.txt
PAVLOV_BIN="${CARGO_TARGET_DIR:-target}/debug/pavlov" \
  "$PY_VENV/bin/python" -m unittest discover --start-directory python --pattern 'test_*.py' --verbose
# --- end of the Python loader ----------------------------------------------------------------------------

# --- the Zenoh wire from Python (tests/python/test_zenoh_wire.py) ----------------------------------------
# The `eclipse-zenoh` package pinned in tests/python/requirements-zenoh.txt (the zenoh crate's version) goes
# into a venv of its own; the test starts two simulated robots and a fleet with the debug binary `cargo test`
# built with the zenoh feature, and talks to them as a lab's script would (docs/src/zenoh-wire.md).
PY_ZENOH="${CARGO_TARGET_DIR:-target}/py-zenoh"
step "the Zenoh wire from Python (tests/python/requirements-zenoh.txt into $PY_ZENOH; unittest)"
[ -x "$PY_ZENOH/bin/python" ] || python3 -m venv "$PY_ZENOH"
"$PY_ZENOH/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/python/requirements-zenoh.txt
PAVLOV_BIN="${CARGO_TARGET_DIR:-target}/debug/pavlov" \
  "$PY_ZENOH/bin/python" -m unittest discover --start-directory tests/python --pattern 'test_zenoh_*.py' --verbose
# --- end of the Zenoh wire from Python -------------------------------------------------------------------

step "soak: 24 simulated hours of the whole server with faults injected (release build, ~1 min)"
cargo test --profile soak -p pavlov-actors --test soak -- --nocapture
