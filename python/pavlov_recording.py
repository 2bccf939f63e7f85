"""Load a pavlov recording into pandas.

    import pavlov_recording
    rec = pavlov_recording.load("DIR/recording.mcap")  # or the folder DIR, or DIR/ticks.jsonl
    current = rec.ticks.set_index("t_s")["battery_current_mA"]   # a Series over time, in mA
    stalls = rec.events[rec.events["kind"] == "pipeline_stall"]

`load` reads an MCAP recording (`recording.mcap`, as `pavlov serve --record`, the dashboard and the
experiments write it), a JSON Lines recording (`ticks.jsonl`, as `pavlov convert --to jsonl` writes it), or
a folder holding either (the MCAP file first). It returns a `Recording`:

- `ticks`: one row per recorded tick, in the order written, every nested field of pavlov's `TickRecord`
  (`src/record.rs`) flattened to one column, its unit at the end of its name where it has one:
    - `seq`, `t_s` (the tick's scheduled time since the run started, s), `mode`, `obs_age_ticks`;
    - the readings of interest (`sensors`): `overcurrent_left`, `overcurrent_right`, `bump_left`,
      `bump_right`, `battery_current_mA` (negative = discharging), `battery_voltage_mV`,
      `battery_charge_mAh`, `distance_mm` and `angle_deg` (summed over the frames since the previous tick),
      `oi_mode` (packet 35 as reported);
    - `elbow_left_deg`, `elbow_left_avg_deg`, `elbow_right_deg`, `elbow_right_avg_deg`, `skeleton`
      (interaction experiment; NaN / None otherwise);
    - `stimulus`, then per prediction NAME (in the configuration's order) `prediction_NAME` (its value
      before the tick's update) and `threshold_NAME`; `gate`, `rule` (what engaged the gate, or None);
    - `default_left_mm_s`, `default_right_mm_s` (the default policy π), `command_left_mm_s`,
      `command_right_mm_s` (what the robot was told); `safety_stop` (None, `e_stop`, `stale_observation`,
      `link_down`, `robot_tripped`), `estop`, `lateness_us`;
    - `link_up`, `link_state`, `link_mode`, `link_trip`, `link_good_frames`, `link_bad_frames`,
      `link_skipped_bytes`, `link_reconnects`, `link_stale_events`;
    - `behaviour_prob`: the behaviour probability b(A|S) of the tick's command (ε or 1 − ε where a
      stochastic gate, `[control] gate = "stochastic"`, drew π's action or the response; 1.0 for every
      certain choice, which the record leaves out, and in recordings made before the stochastic gate);
    - `forced_stimulus`, `previous_followed_default`, `previous_behaviour_prob` (b of the previous tick's
      command where it was π's, so that an off-policy prediction about π learned with ρ = 1/b; 1.0
      otherwise, where the record leaves it out, and where the tick has no inputs), and the raw sensor
      packets learning saw,
      `raw_<packet>[_<unit>]` in the Open Interface's units (e.g. `raw_current_mA`, `raw_voltage_mV`,
      `raw_requested_left_velocity_mm_s`; `<NA>` where the snapshot lacked the packet);
    - `obs_<name>`: the observation vector scaled to [0, 1] (float32), one column per name of the
      recording's `obs_names`. An MCAP recording does not store it (pavlov recomputes it from the raw
      packets); this module recomputes it the same way (`src/obs.rs`), bit for bit.
  Optional integers are pandas' nullable `Int64` (`<NA>` when absent); optional floats are NaN.
- `events`: one row per event: `id`, `kind`, `after` (the last tick before it took effect; `<NA>` =
  before the first), `tick` (the first tick it applies to), `t_s` (that tick's time), then the event's own
  fields, nested ones joined with `_` (e.g. `action_left_mm_s` of a `teleop`), None where a kind lacks one.
- `config`: the configuration in force, as a dict (`config["sim"]["seed"]` is the run's seed).
- `metadata`: the provenance, as the recording holds it (MCAP: the `pavlov.recording` metadata record, every
  value a string; JSON Lines: the header line without its `config`, `start` and `obs_names`). Every key is
  passed through, including ones this module does not know.
- `learner`: where the run stood when the recording began (`after`, `events_before`, the learner's state).
- `obs_names`, `message_counts` (MCAP: topic -> count from the file's summary statistics), `path`,
  `format` (`"mcap"` or `"jsonl"`), `torn` (True for an MCAP file without its summary, cut by a kill or copied
  while being written: it is read from the start up to its last complete chunk, with a warning).

It needs only the `mcap` packages (`mcap`, `mcap-protobuf-support`, `protobuf`, `zstandard`, `lz4`), pandas
and numpy, pinned in python/requirements.txt; the tick protobuf is decoded from the schema the file
carries (no code generated from pavlov's sources).
"""

from __future__ import annotations

import json
import math
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Optional, Union

import numpy as np
import pandas as pd

__all__ = ["Recording", "load", "MCAP_FILE", "JSONL_FILE"]

MCAP_FILE = "recording.mcap"
JSONL_FILE = "ticks.jsonl"

# The Open Interface's single sensor packets (src/oi/packets.rs, PACKETS): id -> (name, unit). Units
# become column suffixes; "bits", "bool", "code" and "" (no physical unit) add none.
PACKETS: dict[int, tuple[str, str]] = {
    7: ("bumps_wheel_drops", "bits"), 8: ("wall", "bool"), 9: ("cliff_left", "bool"),
    10: ("cliff_front_left", "bool"), 11: ("cliff_front_right", "bool"), 12: ("cliff_right", "bool"),
    13: ("virtual_wall", "bool"), 14: ("overcurrents", "bits"), 15: ("dirt_detect", ""),
    16: ("unused_16", ""), 17: ("ir_omni", "code"), 18: ("buttons", "bits"), 19: ("distance", "mm"),
    20: ("angle", "deg"), 21: ("charging_state", "code"), 22: ("voltage", "mV"), 23: ("current", "mA"),
    24: ("temperature", "degC"), 25: ("battery_charge", "mAh"), 26: ("battery_capacity", "mAh"),
    27: ("wall_signal", ""), 28: ("cliff_left_signal", ""), 29: ("cliff_front_left_signal", ""),
    30: ("cliff_front_right_signal", ""), 31: ("cliff_right_signal", ""),
    32: ("cargo_bay_digital_inputs", "bits"), 33: ("cargo_bay_analog_signal", ""),
    34: ("charging_sources", "bits"), 35: ("oi_mode", "code"), 36: ("song_number", ""),
    37: ("song_playing", "bool"), 38: ("stream_packet_count", ""), 39: ("requested_velocity", "mm/s"),
    40: ("requested_radius", "mm"), 41: ("requested_right_velocity", "mm/s"),
    42: ("requested_left_velocity", "mm/s"), 43: ("left_encoder", "counts"),
    44: ("right_encoder", "counts"), 45: ("light_bumper", "bits"), 46: ("light_bump_left_signal", ""),
    47: ("light_bump_front_left_signal", ""), 48: ("light_bump_center_left_signal", ""),
    49: ("light_bump_center_right_signal", ""), 50: ("light_bump_front_right_signal", ""),
    51: ("light_bump_right_signal", ""), 52: ("ir_left", "code"), 53: ("ir_right", "code"),
    54: ("left_motor_current", "mA"), 55: ("right_motor_current", "mA"),
    56: ("main_brush_current", "mA"), 57: ("side_brush_current", "mA"), 58: ("stasis", "bits"),
}
_NO_UNIT = {"bits", "bool", "code", ""}


def raw_column(packet: int) -> str:
    """The `ticks` column of raw packet `packet`: `raw_<name>[_<unit>]`, e.g. `raw_current_mA`."""
    name, unit = PACKETS.get(packet, (f"packet_{packet}", ""))
    if unit in _NO_UNIT:
        return f"raw_{name}"
    return f"raw_{name}_{unit.replace('/', '_')}"


# The observation layouts (src/obs.rs, CREATE1_DIMS and CREATE2_DIMS): (name, packet, bit, min, max); a
# bit dimension (bit not None) is that bit of the packet, any other clamp((raw - min) / (max - min), 0, 1).
_DIST, _ANG = (-10.0, 10.0), (-5.0, 5.0)
_VOLT, _CURR, _TEMP, _CHG = (12000.0, 18000.0), (-3000.0, 1500.0), (0.0, 50.0), (0.0, 3000.0)
_VEL, _RAD, _SIG12, _MOTOR = (-500.0, 500.0), (-2000.0, 2000.0), (0.0, 4095.0), (-500.0, 1500.0)
_Dim = tuple[str, int, Optional[int], float, float]


def _v(name: str, packet: int, r: tuple[float, float]) -> _Dim:
    return (name, packet, None, r[0], r[1])


def _b(name: str, packet: int, bit: int) -> _Dim:
    return (name, packet, bit, 0.0, 1.0)


OBS_CREATE1: list[_Dim] = [
    _b("bump_right", 7, 0), _b("bump_left", 7, 1), _b("wheel_drop_right", 7, 2),
    _b("wheel_drop_left", 7, 3), _b("wheel_drop_caster", 7, 4),
    _v("wall", 8, (0, 1)), _v("cliff_left", 9, (0, 1)), _v("cliff_front_left", 10, (0, 1)),
    _v("cliff_front_right", 11, (0, 1)), _v("cliff_right", 12, (0, 1)), _v("virtual_wall", 13, (0, 1)),
    _b("overcurrent_ld1", 14, 0), _b("overcurrent_ld0", 14, 1), _b("overcurrent_ld2", 14, 2),
    _b("overcurrent_right_wheel", 14, 3), _b("overcurrent_left_wheel", 14, 4),
    _v("unused_15", 15, (0, 255)), _v("unused_16", 16, (0, 255)), _v("ir_omni", 17, (0, 255)),
    _v("buttons", 18, (0, 5)), _v("distance", 19, _DIST), _v("angle", 20, _ANG),
    _v("charging_state", 21, (0, 5)), _v("voltage", 22, _VOLT), _v("current", 23, _CURR),
    _v("battery_temperature", 24, _TEMP), _v("battery_charge", 25, _CHG),
    _v("battery_capacity", 26, _CHG), _v("wall_signal", 27, _SIG12),
    _v("cliff_left_signal", 28, _SIG12), _v("cliff_front_left_signal", 29, _SIG12),
    _v("cliff_front_right_signal", 30, _SIG12), _v("cliff_right_signal", 31, _SIG12),
    _v("cargo_bay_digital_inputs", 32, (0, 31)), _v("cargo_bay_analog_signal", 33, (0, 1023)),
    _v("charging_sources", 34, (0, 3)), _v("oi_mode", 35, (0, 3)), _v("song_number", 36, (0, 15)),
    _v("song_playing", 37, (0, 1)), _v("stream_packets", 38, (0, 43)),
    _v("requested_velocity", 39, _VEL), _v("requested_radius", 40, _RAD),
    _v("requested_right_velocity", 41, _VEL), _v("requested_left_velocity", 42, _VEL),
]
OBS_CREATE2: list[_Dim] = [
    _b("bump_right", 7, 0), _b("bump_left", 7, 1), _b("wheel_drop_right", 7, 2),
    _b("wheel_drop_left", 7, 3),
    _v("wall", 8, (0, 1)), _v("cliff_left", 9, (0, 1)), _v("cliff_front_left", 10, (0, 1)),
    _v("cliff_front_right", 11, (0, 1)), _v("cliff_right", 12, (0, 1)), _v("virtual_wall", 13, (0, 1)),
    _b("overcurrent_side_brush", 14, 0), _b("overcurrent_main_brush", 14, 2),
    _b("overcurrent_right_wheel", 14, 3), _b("overcurrent_left_wheel", 14, 4),
    _v("dirt_detect", 15, (0, 255)), _v("unused_16", 16, (0, 255)), _v("ir_omni", 17, (0, 255)),
    _v("buttons", 18, (0, 255)), _v("distance", 19, _DIST), _v("angle", 20, _ANG),
    _v("charging_state", 21, (0, 6)), _v("voltage", 22, _VOLT), _v("current", 23, _CURR),
    _v("battery_temperature", 24, _TEMP), _v("battery_charge", 25, _CHG),
    _v("battery_capacity", 26, _CHG), _v("wall_signal", 27, (0, 1023)),
    _v("cliff_left_signal", 28, _SIG12), _v("cliff_front_left_signal", 29, _SIG12),
    _v("cliff_front_right_signal", 30, _SIG12), _v("cliff_right_signal", 31, _SIG12),
    _v("unused_32", 32, (0, 255)), _v("unused_33", 33, (0, 65535)),
    _v("charging_sources", 34, (0, 3)), _v("oi_mode", 35, (0, 4)), _v("song_number", 36, (0, 15)),
    _v("song_playing", 37, (0, 1)), _v("stream_packets", 38, (0, 108)),
    _v("requested_velocity", 39, _VEL), _v("requested_radius", 40, _RAD),
    _v("requested_right_velocity", 41, _VEL), _v("requested_left_velocity", 42, _VEL),
    _v("left_encoder_counts", 43, (-32768, 32767)), _v("right_encoder_counts", 44, (-32768, 32767)),
    _b("light_bumper_left", 45, 0), _b("light_bumper_front_left", 45, 1),
    _b("light_bumper_center_left", 45, 2), _b("light_bumper_center_right", 45, 3),
    _b("light_bumper_front_right", 45, 4), _b("light_bumper_right", 45, 5),
    _v("light_bump_left_signal", 46, _SIG12), _v("light_bump_front_left_signal", 47, _SIG12),
    _v("light_bump_center_left_signal", 48, _SIG12), _v("light_bump_center_right_signal", 49, _SIG12),
    _v("light_bump_front_right_signal", 50, _SIG12), _v("light_bump_right_signal", 51, _SIG12),
    _v("ir_left", 52, (0, 255)), _v("ir_right", 53, (0, 255)),
    _v("left_motor_current", 54, _MOTOR), _v("right_motor_current", 55, _MOTOR),
    _v("main_brush_current", 56, _MOTOR), _v("side_brush_current", 57, _MOTOR),
    _b("stasis_toggling", 58, 0), _b("stasis_disabled", 58, 1),
]


@dataclass
class Recording:
    """One recording, loaded (see the module's documentation for every column)."""

    ticks: pd.DataFrame
    events: pd.DataFrame
    config: dict[str, Any]
    metadata: dict[str, Any]
    learner: Optional[dict[str, Any]]
    obs_names: list[str]
    path: Path
    format: str
    message_counts: Optional[dict[str, int]] = field(default=None)
    torn: bool = False

    @property
    def seed(self) -> Optional[int]:
        """The run's seed: the configuration's `[sim] seed`."""
        seed = self.config.get("sim", {}).get("seed")
        return None if seed is None else int(seed)


def load(path: Union[str, Path]) -> Recording:
    """Loads the recording at `path`: an MCAP file, a JSON Lines file, or a folder holding
    `recording.mcap` (preferred) or `ticks.jsonl`. Raises `FileNotFoundError` when there is none and
    `ValueError` when the file is not a pavlov recording."""
    p = Path(path)
    if p.is_dir():
        if (p / MCAP_FILE).is_file():
            p = p / MCAP_FILE
        elif (p / JSONL_FILE).is_file():
            p = p / JSONL_FILE
        else:
            raise FileNotFoundError(f"{path}: no {MCAP_FILE} or {JSONL_FILE} in this folder")
    if not p.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with open(p, "rb") as f:
        magic = f.read(8)
    if magic.startswith(b"\x89MCAP"):
        return _load_mcap(p)
    if magic.lstrip().startswith(b"{"):
        return _load_jsonl(p)
    raise ValueError(f"{p}: neither an MCAP file nor JSON Lines")


# ---------------------------------------------------------------------------------------------------
# Building the ticks table


class _Columns:
    """Column lists filled one tick at a time."""

    def __init__(self) -> None:
        self.cols: dict[str, list[Any]] = {}
        self.n = 0
        # Per tick: predictions (name -> (value, threshold)), raw packets (id -> value), obs (list or None).
        self.predictions: list[dict[str, tuple[float, float]]] = []
        self.raw: list[Optional[dict[int, int]]] = []
        self.obs: list[Optional[list[Optional[float]]]] = []

    def put(self, name: str, value: Any) -> None:
        self.cols.setdefault(name, []).append(value)


_INT_COLUMNS = [
    "seq", "distance_mm", "angle_deg", "default_left_mm_s", "default_right_mm_s", "command_left_mm_s",
    "command_right_mm_s", "lateness_us", "link_good_frames", "link_bad_frames", "link_skipped_bytes",
    "link_reconnects", "link_stale_events",
]
_NULLABLE_INT_COLUMNS = [
    "obs_age_ticks", "battery_current_mA", "battery_voltage_mV", "battery_charge_mAh", "oi_mode", "link_mode",
]
_BOOL_COLUMNS = ["overcurrent_left", "overcurrent_right", "bump_left", "bump_right", "stimulus", "gate",
                 "estop", "link_up"]
_NULLABLE_BOOL_COLUMNS = ["forced_stimulus", "previous_followed_default"]
_FLOAT_COLUMNS = ["t_s", "elbow_left_deg", "elbow_left_avg_deg", "elbow_right_deg", "elbow_right_avg_deg",
                  "behaviour_prob", "previous_behaviour_prob"]


def _obs_layout(obs_names: list[str]) -> Optional[list[_Dim]]:
    """The layout whose names are `obs_names`, if this module knows it."""
    for layout in (OBS_CREATE1, OBS_CREATE2):
        if [d[0] for d in layout] == obs_names:
            return layout
    return None


def _frame(c: _Columns, obs_names: list[str], prediction_order: list[str]) -> pd.DataFrame:
    n = c.n
    data: dict[str, Any] = {}
    for name, values in c.cols.items():
        if name in _INT_COLUMNS:
            data[name] = np.asarray(values, dtype=np.int64)
        elif name in _NULLABLE_INT_COLUMNS:
            data[name] = pd.array(values, dtype="Int64")
        elif name in _BOOL_COLUMNS:
            data[name] = np.asarray(values, dtype=bool)
        elif name in _NULLABLE_BOOL_COLUMNS:
            data[name] = pd.array(values, dtype="boolean")
        elif name in _FLOAT_COLUMNS:
            data[name] = np.asarray([math.nan if v is None else v for v in values], dtype=np.float64)
        else:
            data[name] = pd.Series(values, dtype=object)
    # Predictions: one value and one threshold column per name.
    names = list(prediction_order)
    for per_tick in c.predictions:
        for name in per_tick:
            if name not in names:
                names.append(name)
    for name in names:
        predicted = np.full(n, np.nan)
        thresholds = np.full(n, np.nan)
        for i, per_tick in enumerate(c.predictions):
            got = per_tick.get(name)
            if got is not None:
                predicted[i], thresholds[i] = got
        data[f"prediction_{name}"] = predicted
        data[f"threshold_{name}"] = thresholds
    # Raw packets: one column per packet any tick carried, <NA> where a tick lacked it.
    ids = sorted({i for r in c.raw if r for i in r})
    raw = np.zeros((n, max(ids) + 1 if ids else 0), dtype=np.int64)
    present = np.zeros_like(raw, dtype=bool)
    for row, r in enumerate(c.raw):
        if r:
            for i, v in r.items():
                raw[row, i] = v
                present[row, i] = True
    for i in ids:
        data[raw_column(i)] = pd.arrays.IntegerArray(raw[:, i].copy(), ~present[:, i])
    # The observation: as stored where a tick stored it, else recomputed from its raw packets.
    if obs_names:
        obs = _observations(c, obs_names, raw, present)
        if obs is not None:
            for j, name in enumerate(obs_names):
                data[f"obs_{name}"] = obs[:, j]
    frame = pd.DataFrame(data, index=pd.RangeIndex(n))
    return frame[_ordered(list(frame.columns))]


def _observations(c: _Columns, obs_names: list[str], raw: np.ndarray,
                  present: np.ndarray) -> Optional[np.ndarray]:
    n, dims = c.n, len(obs_names)
    out = np.full((n, dims), np.nan, dtype=np.float32)
    need = [i for i, o in enumerate(c.obs) if o is None and c.raw[i] is not None]
    for i, o in enumerate(c.obs):
        if o is not None:
            if len(o) != dims:
                raise ValueError(f"tick {i}: {len(o)} observation values for {dims} names")
            out[i] = [math.nan if x is None else x for x in o]
    if need:
        layout = _obs_layout(obs_names)
        if layout is None:
            warnings.warn("the recording's obs_names are not a layout this module knows (src/obs.rs): "
                          "the obs_ columns are left out", stacklevel=3)
            return None
        rows = np.asarray(need)
        for j, (_, packet, bit, lo, hi) in enumerate(layout):
            if packet >= raw.shape[1]:
                continue
            v = raw[rows, packet]
            if bit is not None:
                scaled = ((v >> bit) & 1).astype(np.float64)
            else:
                scaled = np.clip((v.astype(np.float64) - lo) / (hi - lo), 0.0, 1.0)
            scaled[~present[rows, packet]] = np.nan
            out[rows, j] = scaled.astype(np.float32)
    return out


_FIRST = ["seq", "t_s", "mode", "obs_age_ticks", "overcurrent_left", "overcurrent_right", "bump_left",
          "bump_right", "battery_current_mA", "battery_voltage_mV", "battery_charge_mAh", "distance_mm",
          "angle_deg", "oi_mode", "elbow_left_deg", "elbow_left_avg_deg", "elbow_right_deg",
          "elbow_right_avg_deg", "skeleton", "stimulus"]
_AFTER_PREDICTIONS = ["gate", "rule", "default_left_mm_s", "default_right_mm_s", "command_left_mm_s",
                      "command_right_mm_s", "safety_stop", "estop", "lateness_us", "link_up", "link_state",
                      "link_mode", "link_trip", "link_good_frames", "link_bad_frames", "link_skipped_bytes",
                      "link_reconnects", "link_stale_events", "forced_stimulus", "previous_followed_default"]


def _ordered(columns: list[str]) -> list[str]:
    """The record's field order: fixed fields, predictions, the rest, raw packets, obs."""
    have = set(columns)
    preds = [c for c in columns if c.startswith(("prediction_", "threshold_"))]
    raw = [c for c in columns if c.startswith("raw_")]
    obs = [c for c in columns if c.startswith("obs_") and c != "obs_age_ticks"]
    fixed = [c for c in _FIRST if c in have] + preds + [c for c in _AFTER_PREDICTIONS if c in have]
    rest = [c for c in columns if c not in set(fixed) | set(raw) | set(obs)]
    return fixed + rest + raw + obs


def _prediction_names(config: dict[str, Any]) -> list[str]:
    """The configuration's prediction names, in its order (the order of the prediction columns)."""
    return [str(p["name"]) for p in config.get("predictions", []) if isinstance(p, dict) and "name" in p]


def _enum_name(enum_type: Any, number: int, prefix: str) -> Optional[str]:
    """`MODE_PAVLOVIAN` -> `pavlovian`, as pavlov's JSON spells it; the zero value (unspecified/none)
    -> None; a number the schema does not name -> its number as a string."""
    if number == 0:
        return None
    v = enum_type.values_by_number.get(number)
    if v is None:
        return str(number)
    name = str(v.name)
    return (name[len(prefix):] if name.startswith(prefix) else name).lower()


# ---------------------------------------------------------------------------------------------------
# MCAP


def _load_mcap(path: Path) -> Recording:
    from mcap_protobuf.decoder import DecoderFactory

    factory = DecoderFactory()
    c = _Columns()
    events: list[tuple[dict[str, Any], Optional[int]]] = []
    config: dict[str, Any] = {}
    learner: Optional[dict[str, Any]] = None
    decode: Optional[Callable[[bytes], Any]] = None
    enums: Optional[dict[str, Any]] = None
    with open(path, "rb") as f:
        messages, metadata_records, counts, torn = _mcap_contents(f, path)
        for schema, channel, message in messages:
            topic = channel.topic
            if topic == "ticks":
                if decode is None:
                    decode = factory.decoder_for(channel.message_encoding, schema)
                    if decode is None:
                        raise ValueError(f"{path}: cannot decode the ticks ({channel.message_encoding})")
                tick = decode(message.data)
                if enums is None:
                    enums = _tick_enums(tick)
                _put_pb_tick(c, tick, enums)
            elif topic == "events":
                events.append((json.loads(message.data), message.log_time))
            elif topic == "config":
                config = json.loads(message.data)
            elif topic == "learner":
                learner = json.loads(message.data)
    if torn:
        warnings.warn(f"{path} ends early (no summary: the recorder was killed, or it is a copy of a recording "
                      f"still being written): {c.n} ticks read, up to its last complete chunk", stacklevel=3)
    metadata: dict[str, Any] = {}
    for name, values in metadata_records:
        if name == "pavlov.recording":
            metadata = values
    names = metadata.get("obs_names", "")
    obs_names = [s for s in names.split(",") if s] if isinstance(names, str) else list(names)
    order = _prediction_names(config)
    period_ms = float(config.get("tick", {}).get("period_ms", 20))
    return Recording(
        ticks=_frame(c, obs_names, order),
        events=_events_frame(events, period_ms),
        config=config,
        metadata=metadata,
        learner=learner,
        obs_names=obs_names,
        path=path,
        format="mcap",
        message_counts=counts,
        torn=torn,
    )


def _mcap_contents(f: Any, path: Path) -> tuple[Iterator[tuple[Any, Any, Any]], list[tuple[str, dict[str, str]]],
                                                  Optional[dict[str, int]], bool]:
    """The messages of an MCAP file in file order, its metadata records, its summary's message counts (None
    without a summary), and whether it ends early.

    A whole file is read through its summary with `mcap`'s reader. A file without a summary or footer (cut
    by a kill, or copied while it was written) is read from the start with `mcap`'s stream reader, CRCs
    checked, up to its last complete record, as pavlov's own reader does."""
    from mcap.exceptions import InvalidMagic, McapError
    from mcap.reader import make_reader
    from mcap.stream_reader import CRCValidationError, StreamReader

    reader = make_reader(f)
    try:
        summary = reader.get_summary()
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    except (McapError, ValueError, EOFError, struct.error):
        summary = None
    if summary is not None and summary.statistics is not None:
        counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        return reader.iter_messages(log_time_order=False), metadata, counts, False

    from mcap.records import Channel, Message, Metadata, Schema

    f.seek(0)
    # No record is longer than the file: a corrupt length cannot make the reader allocate more.
    size = path.stat().st_size
    stream = StreamReader(f, validate_crcs=True, record_size_limit=size)
    torn = False
    found: list[tuple[str, dict[str, str]]] = []
    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    messages: list[tuple[Any, Any, Any]] = []
    try:
        for record in stream.records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels[record.channel_id]
                messages.append((schemas.get(channel.schema_id), channel, record))
            elif isinstance(record, Metadata):
                found.append((record.name, dict(record.metadata)))
    except InvalidMagic as e:
        raise ValueError(f"{path}: not an MCAP file ({e})") from None
    except (McapError, CRCValidationError, EOFError, KeyError, struct.error):
        # Where the stream reader stops before the footer: at the cut (after the last complete record).
        torn = True
    return iter(messages), found, None, torn


def _tick_enums(tick: Any) -> dict[str, Any]:
    d = tick.DESCRIPTOR
    link = d.fields_by_name["link"].message_type
    return {
        "mode": d.fields_by_name["mode"].enum_type,
        "safety_stop": d.fields_by_name["safety_stop"].enum_type,
        "link_state": link.fields_by_name["state"].enum_type,
        "link_trip": link.fields_by_name["trip"].enum_type,
        "skeleton": d.fields_by_name["elbow"].message_type.fields_by_name["skeleton"].enum_type,
    }


def _opt(msg: Any, name: str) -> Any:
    return getattr(msg, name) if msg.HasField(name) else None


def _prob(msg: Any, name: str) -> float:
    """A behaviour probability, written only when it is not 1: 1.0 when absent. The schema declares it
    without presence (a plain `double`), so an absent one reads as proto3's default 0, which no probability
    of an action taken is; a schema older than the field has no such field at all."""
    if name not in msg.DESCRIPTOR.fields_by_name:
        return 1.0
    value = float(getattr(msg, name))
    return 1.0 if value == 0.0 else value


def _put_pb_tick(c: _Columns, t: Any, enums: dict[str, Any]) -> None:
    put = c.put
    put("seq", t.seq)
    put("t_s", t.t_ms / 1000.0)
    put("mode", _enum_name(enums["mode"], t.mode, "MODE_"))
    put("obs_age_ticks", _opt(t, "obs_age_ticks"))
    s = t.sensors
    put("overcurrent_left", s.overcurrent_left)
    put("overcurrent_right", s.overcurrent_right)
    put("bump_left", s.bump_left)
    put("bump_right", s.bump_right)
    put("battery_current_mA", _opt(s, "battery_current_ma"))
    put("battery_voltage_mV", _opt(s, "battery_voltage_mv"))
    put("battery_charge_mAh", _opt(s, "battery_charge_mah"))
    put("distance_mm", s.distance_mm)
    put("angle_deg", s.angle_deg)
    put("oi_mode", _opt(s, "oi_mode"))
    if t.HasField("elbow"):
        e = t.elbow
        put("elbow_left_deg", _opt(e, "left"))
        put("elbow_left_avg_deg", _opt(e, "left_avg"))
        put("elbow_right_deg", _opt(e, "right"))
        put("elbow_right_avg_deg", _opt(e, "right_avg"))
        put("skeleton", _enum_name(enums["skeleton"], e.skeleton, "SKELETON_STATUS_") or "none")
    else:
        for name in ("elbow_left_deg", "elbow_left_avg_deg", "elbow_right_deg", "elbow_right_avg_deg",
                     "skeleton"):
            put(name, None)
    put("stimulus", t.stimulus)
    c.predictions.append({p.name: (p.value, p.threshold) for p in t.predictions})
    put("gate", t.gate)
    put("rule", _opt(t, "rule"))
    put("default_left_mm_s", t.default_action.left_mm_s)
    put("default_right_mm_s", t.default_action.right_mm_s)
    put("command_left_mm_s", t.command.left_mm_s)
    put("command_right_mm_s", t.command.right_mm_s)
    put("safety_stop", _enum_name(enums["safety_stop"], t.safety_stop, "SAFETY_STOP_"))
    put("behaviour_prob", _prob(t, "behaviour_prob"))
    put("estop", t.estop)
    put("lateness_us", t.lateness_us)
    ln = t.link
    put("link_up", ln.up)
    put("link_state", _enum_name(enums["link_state"], ln.state, "LINK_STATE_"))
    put("link_mode", _opt(ln, "mode"))
    put("link_trip", _enum_name(enums["link_trip"], ln.trip, "TRIP_CAUSE_"))
    put("link_good_frames", ln.good_frames)
    put("link_bad_frames", ln.bad_frames)
    put("link_skipped_bytes", ln.skipped_bytes)
    put("link_reconnects", ln.reconnects)
    put("link_stale_events", ln.stale_events)
    if t.HasField("inputs"):
        i = t.inputs
        put("forced_stimulus", i.forced_stimulus)
        put("previous_followed_default", i.previous_followed_default)
        put("previous_behaviour_prob", _prob(i, "previous_behaviour_prob"))
        if i.HasField("values"):
            c.raw.append(_present(list(i.values.values), i.values.present))
        else:
            c.raw.append(None)
    else:
        put("forced_stimulus", None)
        put("previous_followed_default", None)
        put("previous_behaviour_prob", 1.0)
        c.raw.append(None)
    # Field 17: only a record without inputs stores its observation.
    c.obs.append(list(t.obs) if len(t.obs) else None)
    c.n += 1


def _present(values: list[int], mask: int) -> dict[int, int]:
    """Packet id -> value for every bit set in `mask` (slots past the stored ones are 0)."""
    out = {}
    i = 0
    while mask:
        if mask & 1:
            out[i] = values[i] if i < len(values) else 0
        mask >>= 1
        i += 1
    return out


# ---------------------------------------------------------------------------------------------------
# JSON Lines


def _load_jsonl(path: Path) -> Recording:
    c = _Columns()
    events: list[tuple[dict[str, Any], Optional[int]]] = []
    header: Optional[dict[str, Any]] = None
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as e:
                raise ValueError(f"{path}:{number}: not JSON ({e})") from None
            if header is None:
                if "seq" in row or "event" in row:
                    raise ValueError(f"{path}: the first line is not a recording header")
                header = row
            elif "event" in row:
                events.append((row["event"], None))
            else:
                _put_json_tick(c, row)
    if header is None:
        raise ValueError(f"{path}: empty")
    config = header.get("config") or {}
    metadata = {k: v for k, v in header.items() if k not in ("config", "start", "obs_names")}
    obs_names = list(header.get("obs_names") or [])
    order = _prediction_names(config)
    period_ms = float(config.get("tick", {}).get("period_ms", 20))
    return Recording(
        ticks=_frame(c, obs_names, order),
        events=_events_frame(events, period_ms),
        config=config,
        metadata=metadata,
        learner=header.get("start"),
        obs_names=obs_names,
        path=path,
        format="jsonl",
        message_counts=None,
    )


def _put_json_tick(c: _Columns, r: dict[str, Any]) -> None:
    put = c.put
    put("seq", r["seq"])
    put("t_s", r["t_ms"] / 1000.0)
    put("mode", r.get("mode"))
    put("obs_age_ticks", r.get("obs_age_ticks"))
    s = r.get("sensors") or {}
    put("overcurrent_left", bool(s.get("overcurrent_left")))
    put("overcurrent_right", bool(s.get("overcurrent_right")))
    put("bump_left", bool(s.get("bump_left")))
    put("bump_right", bool(s.get("bump_right")))
    put("battery_current_mA", s.get("battery_current_ma"))
    put("battery_voltage_mV", s.get("battery_voltage_mv"))
    put("battery_charge_mAh", s.get("battery_charge_mah"))
    put("distance_mm", s.get("distance_mm", 0))
    put("angle_deg", s.get("angle_deg", 0))
    put("oi_mode", s.get("oi_mode"))
    e = r.get("elbow")
    put("elbow_left_deg", e.get("left") if e else None)
    put("elbow_left_avg_deg", e.get("left_avg") if e else None)
    put("elbow_right_deg", e.get("right") if e else None)
    put("elbow_right_avg_deg", e.get("right_avg") if e else None)
    put("skeleton", e.get("skeleton", "none") if e else None)
    put("stimulus", bool(r.get("stimulus")))
    c.predictions.append({p["name"]: (_f(p.get("value")), _f(p.get("threshold")))
                          for p in r.get("predictions") or []})
    put("gate", bool(r.get("gate")))
    put("rule", r.get("rule"))
    d = r.get("default_action") or {}
    put("default_left_mm_s", d.get("left_mm_s", 0))
    put("default_right_mm_s", d.get("right_mm_s", 0))
    cmd = r.get("command") or {}
    put("command_left_mm_s", cmd.get("left_mm_s", 0))
    put("command_right_mm_s", cmd.get("right_mm_s", 0))
    put("safety_stop", r.get("safety_stop"))
    put("behaviour_prob", float(r.get("behaviour_prob", 1.0)))
    put("estop", bool(r.get("estop")))
    put("lateness_us", r.get("lateness_us", 0))
    ln = r.get("link") or {}
    put("link_up", bool(ln.get("up")))
    put("link_state", ln.get("state", "up"))
    put("link_mode", ln.get("mode"))
    put("link_trip", ln.get("trip"))
    for k in ("good_frames", "bad_frames", "skipped_bytes", "reconnects", "stale_events"):
        put(f"link_{k}", ln.get(k, 0))
    i = r.get("inputs")
    if i is not None:
        put("forced_stimulus", bool(i.get("forced_stimulus")))
        put("previous_followed_default", bool(i.get("previous_followed_default")))
        put("previous_behaviour_prob", float(i.get("previous_behaviour_prob", 1.0)))
        v = i.get("values")
        c.raw.append(_present(v["values"], v["present"]) if v else None)
    else:
        put("forced_stimulus", None)
        put("previous_followed_default", None)
        put("previous_behaviour_prob", 1.0)
        c.raw.append(None)
    obs = r.get("obs")
    c.obs.append(obs if obs else None)
    c.n += 1


def _f(x: Optional[float]) -> float:
    return math.nan if x is None else float(x)


# ---------------------------------------------------------------------------------------------------
# Events


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict) and value:
        for k, v in value.items():
            _flatten(f"{prefix}_{k}" if prefix else k, v, out)
    else:
        out[prefix] = value


def _events_frame(events: Iterable[tuple[dict[str, Any], Optional[int]]], period_ms: float) -> pd.DataFrame:
    rows = []
    for e, log_time in events:
        after = e.get("after")
        tick = 0 if after is None else int(after) + 1
        row: dict[str, Any] = {
            "id": e.get("id"),
            "kind": e.get("kind"),
            "after": after,
            "tick": tick,
            # The MCAP log time is the time of the tick the event applies from; JSON Lines has none, so
            # the same time is computed from the tick period.
            "t_s": log_time / 1e9 if log_time is not None else tick * period_ms / 1000.0,
        }
        for k, v in e.items():
            if k not in ("id", "kind", "after"):
                _flatten(k, v, row)
        rows.append(row)
    columns = ["id", "kind", "after", "tick", "t_s"]
    frame = pd.DataFrame(rows, columns=columns + sorted({k for r in rows for k in r} - set(columns)))
    frame["id"] = frame["id"].astype("Int64")
    frame["after"] = frame["after"].astype("Int64")
    frame["tick"] = frame["tick"].astype(np.int64)
    frame["t_s"] = frame["t_s"].astype(np.float64)
    return frame


def _main(argv: list[str]) -> None:
    """`python pavlov_recording.py PATH`: prints what the recording holds."""
    rec = load(argv[1])
    print(f"{rec.path} ({rec.format}): {len(rec.ticks)} ticks, {len(rec.events)} events, seed {rec.seed}")
    print("metadata:", json.dumps(rec.metadata))
    print("tick columns:", ", ".join(rec.ticks.columns))
    if len(rec.events):
        print(rec.events.to_string(max_rows=20))


if __name__ == "__main__":
    import sys

    _main(sys.argv)
