"""Tests of pavlov_recording against a fresh recording made by the real binary.

    PAVLOV_BIN=target/debug/pavlov python -m unittest -v python/test_pavlov_recording.py

`PAVLOV_BIN` names the `pavlov` binary (tests/run.sh sets it to the one it just built). Nothing is
skipped: without it, or when the binary cannot make a recording, every test fails saying why.

The recording: `pavlov serve --seed 4242 --record DIR` on the simulated Create, stopped with SIGINT after a
few seconds of real time (longer on a loaded machine, until it holds MIN_TICKS ticks), in a temporary folder (its checkpoints go there too); and its JSON Lines form,
written by `pavlov convert DIR --to jsonl`, which carries pavlov's own observation vector. A second one the
same way under the stochastic gate (`StochasticGateRecording`), for the behaviour probabilities.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from mcap.reader import make_reader

sys.path.insert(0, str(Path(__file__).resolve().parent))
import pavlov_recording  # noqa: E402

SEED = 4242
# How long the server runs (real time, ticks of 20 ms: about 150), and the fewest ticks accepted (a loaded
# machine skips some: the ticker counts them, the recording has gaps in seq).
RUN_S = 3.0
MIN_TICKS = 50
SERVE_TIMEOUT_S = 60.0


def _binary() -> Path:
    value = os.environ.get("PAVLOV_BIN")
    if not value:
        raise RuntimeError("PAVLOV_BIN is not set: point it at a built pavlov binary, e.g. "
                           "PAVLOV_BIN=target/debug/pavlov (tests/run.sh sets it)")
    path = Path(value)
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise RuntimeError(f"PAVLOV_BIN={value} is not an executable file")
    return path.resolve()


def _summary_counts(path: Path) -> dict[str, int]:
    """Message counts per topic from the file's summary statistics, read with `mcap` alone."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None, f"{path} has no summary"
    return {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}


def _ticks_so_far(mcap: Path) -> int:
    """The ticks of a recording still being written, up to its last complete chunk (0 before the first)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return len(pavlov_recording.load(mcap).ticks)
    except (OSError, ValueError, KeyError):
        return 0


def _record(tmp: Path, out: Path, args: list[str]) -> None:
    """`pavlov serve --seed SEED --record OUT` (and `args`) in `tmp` for RUN_S seconds of real time after it
    drives the robot, and longer until it has recorded MIN_TICKS ticks, stopped with SIGINT; then `pavlov
    convert OUT --to jsonl` beside it."""
    binary = _binary()
    log_path = tmp / f"serve-{out.name}.log"

    def log() -> str:
        return log_path.read_text(errors="replace")[-4000:]

    mcap = out / pavlov_recording.MCAP_FILE
    with open(log_path, "w+b") as log_file:
        # Port 0: any free port, so that other servers on the machine do not get in the way.
        serve = subprocess.Popen(
            [str(binary), "serve", "--seed", str(SEED), "--bind", "127.0.0.1:0", "--record", str(out), *args],
            cwd=tmp, stdout=log_file, stderr=subprocess.STDOUT)
        try:
            # Real time: RUN_S after the server says it drives the robot.
            deadline = time.monotonic() + SERVE_TIMEOUT_S
            while b"dashboard:" not in log_path.read_bytes():
                if serve.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("pavlov serve did not start:\n" + log())
                time.sleep(0.1)
            time.sleep(RUN_S)
            # A loaded machine records fewer ticks in that time (the ticker skips, the recorder's queue
            # drops): go on until the file, read as it is being written, holds MIN_TICKS.
            while _ticks_so_far(mcap) < MIN_TICKS and serve.poll() is None and time.monotonic() < deadline:
                time.sleep(0.5)
            serve.send_signal(signal.SIGINT)
            status = serve.wait(timeout=SERVE_TIMEOUT_S)
        finally:
            if serve.poll() is None:
                serve.kill()
                serve.wait()
    if status != 0 or not mcap.is_file():
        raise RuntimeError(f"pavlov serve exited with {status}, recording {mcap}:\n" + log())
    convert = subprocess.run([str(binary), "convert", str(out), "--to", "jsonl"],
                             capture_output=True, text=True, timeout=SERVE_TIMEOUT_S)
    if convert.returncode != 0:
        raise RuntimeError(f"pavlov convert failed: {convert.stderr}")


class FreshRecording(unittest.TestCase):
    tmp: Path
    dir: Path
    mcap: Path
    rec: pavlov_recording.Recording

    @classmethod
    def setUpClass(cls) -> None:
        cls.tmp = Path(tempfile.mkdtemp(prefix="pavlov-pyloader-"))
        cls.dir = cls.tmp / "rec"
        cls.mcap = cls.dir / pavlov_recording.MCAP_FILE
        _record(cls.tmp, cls.dir, [])
        cls.rec = pavlov_recording.load(cls.mcap)

    @classmethod
    def tearDownClass(cls) -> None:
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_one_row_per_tick_and_event_as_the_summary_counts(self) -> None:
        counts = _summary_counts(self.mcap)
        self.assertGreaterEqual(counts["ticks"], MIN_TICKS)
        self.assertEqual(len(self.rec.ticks), counts["ticks"])
        self.assertEqual(len(self.rec.events), counts["events"])
        self.assertEqual(self.rec.message_counts, counts)
        self.assertEqual(self.rec.format, "mcap")

    def test_seq_strictly_increasing_and_time_in_seconds(self) -> None:
        t = self.rec.ticks
        self.assertEqual(t["seq"].dtype, np.int64)
        self.assertTrue((np.diff(t["seq"].to_numpy()) > 0).all(), "seq is not strictly increasing")
        # A recording from the run's start holds its first published tick: tick 0 on a quiet machine, a later
        # one when the ticker woke late and skipped the first (it skips rather than bursts; seq counts them).
        self.assertGreaterEqual(int(t["seq"].iloc[0]), 0)
        self.assertLess(int(t["seq"].iloc[0]), len(t), "the recording starts long after the run did")
        period_s = self.rec.config["tick"]["period_ms"] / 1000.0
        np.testing.assert_allclose(t["t_s"], t["seq"] * period_s, rtol=0, atol=1e-9)

    def test_currents_carry_their_unit(self) -> None:
        t = self.rec.ticks
        for name in ("battery_current_mA", "raw_current_mA"):
            self.assertIn(name, t.columns)
            self.assertEqual(t[name].dtype, "Int64", name)
        for name in t.columns:
            # obs_ columns are scaled to [0, 1]; overcurrent ones are flags.
            if "current" in name and not name.startswith("obs_") and "overcurrent" not in name:
                self.assertTrue(name.endswith("_mA"), f"{name} has no unit")
        # The simulated Create discharges while it drives: the current is negative, in mA (about 0.1-1 A).
        current = t["battery_current_mA"].dropna().to_numpy(dtype=np.int64)
        self.assertTrue((current < 0).all() and (current > -5000).all(), current[:10])
        for name in ("battery_voltage_mV", "battery_charge_mAh", "distance_mm", "angle_deg",
                     "command_left_mm_s", "command_right_mm_s", "lateness_us", "raw_voltage_mV"):
            self.assertIn(name, t.columns)
        voltage = t["battery_voltage_mV"].dropna().to_numpy(dtype=np.int64)
        self.assertTrue(((voltage > 12000) & (voltage < 18000)).all(), voltage[:10])

    def test_the_event_kinds_seen(self) -> None:
        e = self.rec.events
        self.assertEqual(list(e.columns[:5]), ["id", "kind", "after", "tick", "t_s"])
        kinds = e["kind"].tolist()
        # The recording opens and closes with its own events; in between, on a loaded machine, the link
        # and the pipeline watchdog may have spoken (nothing else changes in an unattended run).
        self.assertEqual(kinds[0], "recording_started", kinds)
        self.assertEqual(kinds[-1], "recording_stopped", kinds)
        self.assertLessEqual(set(kinds), {"recording_started", "recording_stopped", "link", "pipeline_stall"})
        self.assertTrue((np.diff(e["id"].to_numpy(dtype=np.int64)) > 0).all())
        started, stopped = e.iloc[0], e.iloc[-1]
        self.assertTrue(pd.isna(started["after"]))
        self.assertEqual(started["tick"], 0)
        self.assertEqual(stopped["tick"], stopped["after"] + 1)
        self.assertGreater(stopped["tick"], self.rec.ticks["seq"].iloc[-1])
        period_s = self.rec.config["tick"]["period_ms"] / 1000.0
        self.assertAlmostEqual(stopped["t_s"], stopped["tick"] * period_s, places=9)
        self.assertEqual(e["path"].iloc[0], str(self.mcap))
        self.assertEqual(e["path"].iloc[-1], str(self.mcap))

    def test_config_and_metadata(self) -> None:
        self.assertEqual(self.rec.config["sim"]["seed"], SEED)
        self.assertEqual(self.rec.seed, SEED)
        meta = self.rec.metadata
        self.assertEqual(meta["seed"], str(SEED))
        self.assertTrue(meta["program"].startswith("pavlov "), meta)
        self.assertTrue(meta["format"].startswith("pavlov-recording/"), meta)
        self.assertEqual(meta["robot_model"], self.rec.config["robot"]["model"])
        learner = self.rec.learner
        assert learner is not None
        self.assertIsNone(learner["after"])
        self.assertEqual(learner["events_before"], 1)

    def test_predictions_and_observation_columns(self) -> None:
        t = self.rec.ticks
        names = [p["name"] for p in self.rec.config["predictions"]]
        self.assertTrue(names)
        for name in names:
            self.assertEqual(t[f"prediction_{name}"].dtype, np.float64)
            self.assertTrue(np.isfinite(t[f"prediction_{name}"]).all())
            self.assertIn(f"threshold_{name}", t.columns)
        self.assertEqual(self.rec.obs_names, self.rec.metadata["obs_names"].split(","))
        obs = [c for c in t.columns if c.startswith("obs_") and c != "obs_age_ticks"]
        self.assertEqual(obs, [f"obs_{n}" for n in self.rec.obs_names])
        values = t[obs].to_numpy()
        self.assertEqual(values.dtype, np.float32)
        self.assertTrue(((values >= 0) & (values <= 1)).all(), "an observation outside [0, 1]")

    def test_the_json_lines_form_loads_to_the_same_frames(self) -> None:
        # pavlov convert writes the observation pavlov computes: ours must equal it bit for bit.
        jsonl = pavlov_recording.load(self.dir / pavlov_recording.JSONL_FILE)
        self.assertEqual(jsonl.format, "jsonl")
        pd.testing.assert_frame_equal(jsonl.ticks, self.rec.ticks, check_exact=True)
        pd.testing.assert_frame_equal(jsonl.events, self.rec.events, check_exact=True)
        self.assertEqual(jsonl.config, self.rec.config)
        self.assertEqual(jsonl.obs_names, self.rec.obs_names)
        obs = [f"obs_{n}" for n in self.rec.obs_names]
        self.assertTrue(np.array_equal(jsonl.ticks[obs].to_numpy().view(np.uint32),
                                       self.rec.ticks[obs].to_numpy().view(np.uint32)))

    def test_a_deterministic_gate_logs_every_command_as_certain(self) -> None:
        # The paper's gate: the record leaves b out; the loader reads it as 1.
        t = self.rec.ticks
        for name in ("behaviour_prob", "previous_behaviour_prob"):
            self.assertEqual(t[name].dtype, np.float64)
            self.assertTrue((t[name] == 1.0).all(), name)

    def test_a_folder_loads_its_mcap_file(self) -> None:
        folder = pavlov_recording.load(self.dir)
        self.assertEqual(folder.path, self.mcap)
        pd.testing.assert_frame_equal(folder.ticks, self.rec.ticks)

    def test_unknown_metadata_keys_are_passed_through(self) -> None:
        # A copy of the recording whose metadata has keys this module does not know (as newer recorders
        # add: commit, dirty, features, command_line, config_hash).
        from mcap.writer import CompressionType, Writer

        extra = {"commit": "0123abc", "dirty": "true", "features": "", "command_line": "pavlov serve",
                 "config_hash": "sha256:00"}
        copy = self.tmp / "copy.mcap"
        with open(self.mcap, "rb") as src, open(copy, "wb") as dst:
            reader = make_reader(src)
            writer = Writer(dst, compression=CompressionType.ZSTD)
            writer.start(profile="", library="test")
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if channel.id not in channels:
                    if schema.id not in schemas:
                        schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                    channels[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding, schemas[schema.id])
                writer.add_message(channels[channel.id], message.log_time, message.data,
                                   message.publish_time, message.sequence)
            for record in reader.iter_metadata():
                writer.add_metadata(record.name, {**record.metadata, **extra})
            writer.finish()
        rec = pavlov_recording.load(copy)
        for key, value in extra.items():
            self.assertEqual(rec.metadata[key], value)
        self.assertEqual(rec.metadata["seed"], str(SEED))
        self.assertEqual(len(rec.ticks), len(self.rec.ticks))

    def test_a_cut_file_reads_up_to_its_last_complete_chunk(self) -> None:
        # As a kill -9 or a copy of a recording still being written leaves it: no summary, no footer.
        data = self.mcap.read_bytes()
        cut = self.tmp / "cut.mcap"
        cut.write_bytes(data[: len(data) * 9 // 10])
        with self.assertWarnsRegex(UserWarning, "ends early"):
            rec = pavlov_recording.load(cut)
        self.assertTrue(rec.torn)
        self.assertFalse(self.rec.torn)
        self.assertIsNone(rec.message_counts)
        n = len(rec.ticks)
        self.assertGreater(n, 0)
        pd.testing.assert_frame_equal(rec.ticks, self.rec.ticks.head(n), check_exact=True)
        self.assertEqual(rec.config, self.rec.config)
        self.assertEqual(rec.metadata, self.rec.metadata)

    def test_events_of_every_shape_flatten_to_columns(self) -> None:
        # Events the unattended run does not make, in the JSON pavlov writes them (src/event.rs), added to
        # the recording's JSON Lines form.
        lines = (self.dir / pavlov_recording.JSONL_FILE).read_text().splitlines()
        extra = [
            {"id": 10, "after": 3, "kind": "teleop", "action": {"left_mm_s": -100, "right_mm_s": 100}},
            {"id": 11, "after": 4, "kind": "params_set", "prediction": "stall", "alpha": 0.01, "lambda": 0.9,
             "threshold": 0.4},
            {"id": 12, "after": 5, "kind": "link", "state": "stale", "trip": None, "reconnects": 0},
            {"id": 13, "after": 6, "kind": "weights_reset"},
        ]
        path = self.tmp / "events.jsonl"
        path.write_text("\n".join(lines[:1] + [json.dumps({"event": e}) for e in extra] + lines[1:]) + "\n")
        e = pavlov_recording.load(path).events
        self.assertEqual(e["kind"].tolist()[:4], ["teleop", "params_set", "link", "weights_reset"])
        teleop = e.iloc[0]
        self.assertEqual((teleop["action_left_mm_s"], teleop["action_right_mm_s"]), (-100, 100))
        self.assertEqual(teleop["tick"], 4)
        self.assertAlmostEqual(teleop["t_s"], 4 * self.rec.config["tick"]["period_ms"] / 1000.0)
        self.assertEqual(e.iloc[1]["alpha"], 0.01)
        self.assertEqual(e.iloc[2]["state"], "stale")
        self.assertTrue(pd.isna(e.iloc[3]["alpha"]))

    def test_what_is_not_a_recording_is_refused(self) -> None:
        empty = self.tmp / "empty"
        empty.mkdir()
        with self.assertRaisesRegex(FileNotFoundError, re.escape("recording.mcap")):
            pavlov_recording.load(empty)
        text = self.tmp / "notes.txt"
        text.write_text("not a recording\n")
        with self.assertRaises(ValueError):
            pavlov_recording.load(text)


if __name__ == "__main__":
    unittest.main()


EPSILON = 0.35


class StochasticGateRecording(unittest.TestCase):
    """A recording under `[control] gate = "stochastic"`: the stall study with ε = 0.35 and a stall prediction
    that starts above its threshold (initial weights 0.1 over 44 active features: 4.4 against 0.5) and
    learns slowly (α = 10⁻⁵), so its rule fires on every tick of the few seconds recorded and each tick's
    command is a draw: π's action with b = ε, or the response with b = 1 − ε."""

    tmp: Path
    dir: Path
    rec: pavlov_recording.Recording

    @classmethod
    def setUpClass(cls) -> None:
        cls.tmp = Path(tempfile.mkdtemp(prefix="pavlov-pyloader-stochastic-"))
        cls.dir = cls.tmp / "stochastic"
        text = (Path(__file__).resolve().parent.parent / "config" / "stall.toml").read_text()
        for old, new in [
            ('response = { kind = "stop" }',
             f'response = {{ kind = "stop" }}\ngate = "stochastic"\nepsilon = {EPSILON}'),
            ("alpha = 0.022727272727272728", "alpha = 0.00001"),
            ("initial_weight = 0.0", "initial_weight = 0.1"),
        ]:
            assert old in text, old
            text = text.replace(old, new, 1)
        config = cls.tmp / "stochastic.toml"
        config.write_text(text)
        _record(cls.tmp, cls.dir, ["--config", str(config)])
        cls.rec = pavlov_recording.load(cls.dir / pavlov_recording.MCAP_FILE)

    @classmethod
    def tearDownClass(cls) -> None:
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_each_command_has_its_behaviour_probability(self) -> None:
        t = self.rec.ticks
        self.assertEqual(self.rec.config["control"]["gate"], "stochastic")
        self.assertGreaterEqual(len(t), MIN_TICKS)
        b = t["behaviour_prob"]
        self.assertEqual(b.dtype, np.float64)
        drawn_pi, drawn_response = (b == EPSILON), (b == 1.0 - EPSILON)
        self.assertTrue((drawn_pi | drawn_response | (b == 1.0)).all(), sorted(set(b)))
        # About 0.35 and 0.65 of the ticks each: both occur (P(none of either in 50 draws) < 1e-9).
        self.assertGreater(int(drawn_pi.sum()), 0)
        self.assertGreater(int(drawn_response.sum()), 0)
        # π's action where b = ε (the response, stop, where b = 1 − ε).
        pi = t[drawn_pi]
        self.assertTrue((pi["command_left_mm_s"] == pi["default_left_mm_s"]).all())
        self.assertTrue((pi["command_right_mm_s"] == pi["default_right_mm_s"]).all())

    def test_the_next_tick_carries_the_previous_commands_probability(self) -> None:
        # Learning records b of the previous tick's command where that command was π's (ρ = 1/b), and 1
        # otherwise (ρ = 0 whatever b is; also when actuation's record of the previous tick had not reached
        # learning yet, which then counts π as not followed).
        t = self.rec.ticks
        p = t["previous_behaviour_prob"].to_numpy()
        self.assertEqual(t["previous_behaviour_prob"].dtype, np.float64)
        followed = t["previous_followed_default"].fillna(False).to_numpy(dtype=bool)
        self.assertTrue((p[~followed] == 1.0).all(), sorted(set(p[~followed])))
        # Where the previous tick is in the recording (none skipped between), its b is the one carried.
        seq = t["seq"].to_numpy()
        after_previous = np.concatenate([[False], np.diff(seq) == 1])
        b_before = np.concatenate([[np.nan], t["behaviour_prob"].to_numpy()[:-1]])
        carried = after_previous & followed
        self.assertGreater(int(carried.sum()), 0, "no tick after one of π's actions")
        np.testing.assert_array_equal(p[carried], b_before[carried])
        self.assertTrue((p[carried] == EPSILON).any(), sorted(set(p[carried])))

    def test_the_json_lines_form_has_the_same_probabilities(self) -> None:
        jsonl = pavlov_recording.load(self.dir / pavlov_recording.JSONL_FILE)
        for name in ("behaviour_prob", "previous_behaviour_prob"):
            np.testing.assert_array_equal(jsonl.ticks[name].to_numpy(), self.rec.ticks[name].to_numpy())
        pd.testing.assert_frame_equal(jsonl.ticks, self.rec.ticks, check_exact=True)
