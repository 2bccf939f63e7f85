#!/usr/bin/env bash
# Installs what the dashboard's browser test needs (Debian Chromium from apt, the npm packages from the
# lock file; playwright-core never downloads a browser) and runs the Node unit tests and the end-to-end
# browser test. Run from anywhere in the repository; needs root (or sudo) for apt-get.
set -euo pipefail
cd "$(dirname "$0")/../.."

if ! command -v chromium >/dev/null 2>&1 && [ ! -x /usr/bin/chromium ]; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends chromium
fi

npm ci --prefix web --no-audit --no-fund
npm test --prefix web
cargo test -p pavlov-actors --test e2e dashboard::browser -- --nocapture
echo "screenshots: target/dashboard*.png"
