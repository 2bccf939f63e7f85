//! The robustness study (`pavlov experiment stall --variations`): the stall study's design, repeated under
//! plausible variations of the world, the robot, its sensing, the default policy, the link, and the one
//! reading of the specification the simulator rests on (the 1.0 A limit of a stalled wheel's current).
//!
//! Each variation is one change to the base configuration (`[sim.params]`, `[sim] faults`, `[sim]
//! lab_variation` or the default policy's speed), made one at a time, with its basis: a fact in
//! `docs/SOURCES.md` (tag and page) or an *estimate* (no source gives the range; the text says why the
//! range is plausible). Every range below was written down before any outcome under it was seen, and none
//! was changed after; the table reports what comes out.
//!
//! Every variation runs the same interleaved plan with the same run seeds (run `i` of every variation
//! uses the seed of run `i` of the plain study), so the variations differ by their change alone. All runs
//! of all variations go through the one pool (`crate::experiment::runner::run_all`), interleaved across
//! variations (run 0 of every variation, then run 1, …); each variation is analysed with the stall
//! study's own statistics (`super::analyse`). The study writes `variations.md`, `variations.csv`,
//! `variations.json` and the forest plot `fig_variations.{svg,png}` (`super::variations_forest`).

use std::path::Path;
use std::time::Instant;

use pavlov::config::Config;
use pavlov::control::Policy;
use serde::Serialize;

use super::analysis::Comparison;
use super::run::{RunResult, RunSpec};
use super::{StallOptions, WINDOW_S, analyse, plan};
use crate::experiment::run_all;

/// Where a variation's range comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", content = "text", rename_all = "snake_case")]
pub enum Basis {
    /// A fact in `docs/SOURCES.md` (the text cites it).
    Source(&'static str),
    /// No source gives the range; the text says why it is plausible.
    Estimate(&'static str),
}

impl Basis {
    /// `source: …` or `estimate: …`.
    pub fn label(&self) -> String {
        match self {
            Basis::Source(t) => format!("source: {t}"),
            Basis::Estimate(t) => format!("estimate: {t}"),
        }
    }
}

/// One variation: a change to the base configuration and why its range is plausible.
#[derive(Debug, Clone, Copy)]
pub struct Variation {
    /// Short name, unique (a row of the table).
    pub name: &'static str,
    /// `baseline`, `reading`, `world`, `robot`, `sensing`, `policy` or `link`.
    pub group: &'static str,
    /// The change, as configuration.
    pub change: &'static str,
    /// Its basis.
    pub basis: Basis,
    /// Makes the change.
    apply: fn(&mut Config),
}

impl Variation {
    /// `base` with this variation's change.
    pub fn config(&self, base: &Config) -> Config {
        let mut c = base.clone();
        (self.apply)(&mut c);
        c
    }
}

fn nothing(_: &mut Config) {}

/// The straight speed of the stall cycle, keeping its turn speed (the turns' 133° is matched to the
/// enclosure's corners, not to the straight speed; `pavlov::control::policy`).
fn drive_speed(c: &mut Config, mm_s: i16) {
    let turn = match c.control.default_policy {
        Policy::StallCycle { turn_mm_s, .. } => turn_mm_s,
        _ => pavlov::control::policy::STALL_TURN_MM_S,
    };
    c.control.default_policy = Policy::StallCycle {
        drive_mm_s: mm_s,
        turn_mm_s: turn,
    };
}

/// The whole stall cycle at another speed: straight at `mm_s`, the in-place turns at half of it per wheel,
/// the ratio of the default cycle (200 and 100 mm/s; `pavlov::control::StallDefaultPolicy::new`). The turns
/// last 3 s as before, so they turn through a different angle (≈ 67° at 100 mm/s, ≈ 200° at 300 mm/s
/// instead of ≈ 133°): the legs no longer head back across the enclosure the same way.
fn cycle_speed(c: &mut Config, mm_s: i16) {
    c.control.default_policy = Policy::StallCycle {
        drive_mm_s: mm_s,
        turn_mm_s: mm_s / 2,
    };
}

/// Every variation of the study, the unchanged configuration first.
pub const VARIATIONS: [Variation; 27] = [
    Variation {
        name: "baseline",
        group: "baseline",
        change: "none (config/stall.toml: lab variation on, 200 mm/s, 1.0 A limit, no faults)",
        basis: Basis::Source(
            "[paper] design; the simulator's documented parameters (src/sim/params.rs)",
        ),
        apply: nothing,
    },
    Variation {
        name: "no current limit",
        group: "reading",
        change: "[sim.params] limit_wheel_current = false",
        basis: Basis::Source(
            "[C1 p10, p17]: \"the current is limited and the overcurrent flag is set\" is written on the \
             low side drivers' page; read as not applying to the wheels, a stalled wheel draws its full demand",
        ),
        apply: |c| c.sim.params.limit_wheel_current = Some(false),
    },
    Variation {
        name: "enclosure 0.8 m",
        group: "world",
        change: "[sim.params] enclosure_leg_m = 0.8",
        basis: Basis::Estimate(
            "[paper]: short walls \"one meter\"; ±20 % for a rebuilt enclosure (no source gives a tolerance)",
        ),
        apply: |c| c.sim.params.enclosure_leg_m = Some(0.8),
    },
    Variation {
        name: "enclosure 1.2 m",
        group: "world",
        change: "[sim.params] enclosure_leg_m = 1.2",
        basis: Basis::Estimate(
            "[paper]: short walls \"one meter\"; ±20 % for a rebuilt enclosure (no source gives a tolerance)",
        ),
        apply: |c| c.sim.params.enclosure_leg_m = Some(1.2),
    },
    Variation {
        name: "no lab variation",
        group: "world",
        change: "[sim] lab_variation = false",
        basis: Basis::Source(
            "the simulator's documented default (config/README.md): every run from the centroid, 91 % \
             charge [create_robot#64 sample], nominal friction",
        ),
        apply: |c| c.sim.lab_variation = false,
    },
    Variation {
        name: "payload 1.5 kg",
        group: "robot",
        change: "[sim.params] payload_kg = 1.5",
        basis: Basis::Estimate(
            "[paper]: \"approximately two kilograms\"; ±25 % for \"approximately\"",
        ),
        apply: |c| c.sim.params.payload_kg = Some(1.5),
    },
    Variation {
        name: "payload 2.5 kg",
        group: "robot",
        change: "[sim.params] payload_kg = 2.5",
        basis: Basis::Estimate(
            "[paper]: \"approximately two kilograms\"; ±25 % for \"approximately\"",
        ),
        apply: |c| c.sim.params.payload_kg = Some(2.5),
    },
    Variation {
        name: "friction × 0.6",
        group: "robot",
        change: "[sim.params] friction_scale = 0.6",
        basis: Basis::Estimate(
            "friction values are estimates (src/sim/params.rs, [HR p378] ≈500 mA driving); twice the lab \
             variation's ±20 % for another floor or gearbox",
        ),
        apply: |c| c.sim.params.friction_scale = Some(0.6),
    },
    Variation {
        name: "friction × 1.5",
        group: "robot",
        change: "[sim.params] friction_scale = 1.5",
        basis: Basis::Estimate(
            "friction values are estimates (src/sim/params.rs, [HR p378] ≈500 mA driving); a rougher floor \
             or a worn gearbox",
        ),
        apply: |c| c.sim.params.friction_scale = Some(1.5),
    },
    Variation {
        name: "stall current 1.25 A",
        group: "robot",
        change: "[sim.params] stall_current_a = 1.25",
        basis: Basis::Estimate(
            "the 1.5 A demand is an estimate \"comfortably above the 1.0 A limit [C1 p17]\"; just above it",
        ),
        apply: |c| c.sim.params.stall_current_a = Some(1.25),
    },
    Variation {
        name: "stall current 2.5 A",
        group: "robot",
        change: "[sim.params] stall_current_a = 2.5",
        basis: Basis::Estimate(
            "the 1.5 A demand is an estimate; 2.5 A for a stiffer motor (a stall load of 2–3 A is what the \
             pack's internal resistance is sized for, src/sim/params.rs)",
        ),
        apply: |c| c.sim.params.stall_current_a = Some(2.5),
    },
    Variation {
        name: "battery 0.2 Ω",
        group: "robot",
        change: "[sim.params] internal_resistance_ohm = 0.2",
        basis: Basis::Estimate("the 0.35 Ω pack resistance is an estimate; a fresh pack"),
        apply: |c| c.sim.params.internal_resistance_ohm = Some(0.2),
    },
    Variation {
        name: "battery 0.6 Ω",
        group: "robot",
        change: "[sim.params] internal_resistance_ohm = 0.6",
        basis: Basis::Estimate("the 0.35 Ω pack resistance is an estimate; an aged NiMH pack"),
        apply: |c| c.sim.params.internal_resistance_ohm = Some(0.6),
    },
    Variation {
        name: "current noise 0 mA",
        group: "sensing",
        change: "[sim.params] current_noise_ma = 0",
        basis: Basis::Estimate("the 6 mA noise is an estimate; a clean reading"),
        apply: |c| c.sim.params.current_noise_ma = Some(0.0),
    },
    Variation {
        name: "current noise 20 mA",
        group: "sensing",
        change: "[sim.params] current_noise_ma = 20",
        basis: Basis::Estimate("the 6 mA noise is an estimate; about three times it"),
        apply: |c| c.sim.params.current_noise_ma = Some(20.0),
    },
    Variation {
        name: "current filter 15 ms",
        group: "sensing",
        change: "[sim.params] current_sense_tau_s = 0.015",
        basis: Basis::Estimate(
            "the 30 ms filter is an estimate (\"a control cycle or two\"); one 15 ms cycle [C1 p14]",
        ),
        apply: |c| c.sim.params.current_sense_tau_s = Some(0.015),
    },
    Variation {
        name: "current filter 60 ms",
        group: "sensing",
        change: "[sim.params] current_sense_tau_s = 0.06",
        basis: Basis::Estimate("the 30 ms filter is an estimate; four 15 ms cycles [C1 p14]"),
        apply: |c| c.sim.params.current_sense_tau_s = Some(0.06),
    },
    Variation {
        name: "over-current flag sharp",
        group: "sensing",
        change: "[sim.params] overcurrent_scale_a = 0.06",
        basis: Basis::Estimate("the flag's 0.12 A softness is an estimate; half of it"),
        apply: |c| c.sim.params.overcurrent_scale_a = Some(0.06),
    },
    Variation {
        name: "over-current flag soft",
        group: "sensing",
        change: "[sim.params] overcurrent_scale_a = 0.24",
        basis: Basis::Estimate(
            "the flag's 0.12 A softness is an estimate; twice it (more isolated flags while driving)",
        ),
        apply: |c| c.sim.params.overcurrent_scale_a = Some(0.24),
    },
    Variation {
        name: "straight 100 mm/s",
        group: "policy",
        change: "default_policy = stall_cycle, drive_mm_s = 100, turn_mm_s = 100 (turns unchanged)",
        basis: Basis::Estimate(
            "[paper] gives no speed; 200 mm/s was chosen from the geometry (src/control/policy.rs); 100 \
             mm/s still reaches a wall within a 7 s leg (0.7 m)",
        ),
        apply: |c| drive_speed(c, 100),
    },
    Variation {
        name: "straight 300 mm/s",
        group: "policy",
        change: "default_policy = stall_cycle, drive_mm_s = 300, turn_mm_s = 100 (turns unchanged)",
        basis: Basis::Estimate(
            "[paper] gives no speed; 300 mm/s, within the 500 mm/s Drive Direct limit [C1 p9]",
        ),
        apply: |c| drive_speed(c, 300),
    },
    Variation {
        name: "cycle 100 mm/s",
        group: "policy",
        change: "default_policy = stall_cycle, drive_mm_s = 100, turn_mm_s = 50 (turns slowed too)",
        basis: Basis::Estimate(
            "[paper] gives no speed for the straights or the turns; the whole cycle at half speed, turns \
             at half the straight speed as in the default (≈ 67° per 3 s turn instead of ≈ 133°)",
        ),
        apply: |c| cycle_speed(c, 100),
    },
    Variation {
        name: "cycle 300 mm/s",
        group: "policy",
        change: "default_policy = stall_cycle, drive_mm_s = 300, turn_mm_s = 150 (turns sped up too)",
        basis: Basis::Estimate(
            "[paper] gives no speed; the whole cycle at 1.5× speed, turns at half the straight speed as in \
             the default (≈ 200° per 3 s turn), within the 500 mm/s Drive Direct limit [C1 p9]",
        ),
        apply: |c| cycle_speed(c, 300),
    },
    Variation {
        name: "link delay 30 ms",
        group: "link",
        change: "[sim] faults = \"delay_ms=30\"",
        basis: Basis::Estimate(
            "the soak preset's steady latency (a USB adapter's latency timer or a Bluetooth bridge); the \
             paper's robot was on a Bluetooth link",
        ),
        apply: |c| c.sim.faults = "delay_ms=30".into(),
    },
    Variation {
        name: "link delay 60 ms",
        group: "link",
        change: "[sim] faults = \"delay_ms=60\"",
        basis: Basis::Estimate(
            "twice the soak preset's latency, still below the 100 ms staleness limit",
        ),
        apply: |c| c.sim.faults = "delay_ms=60".into(),
    },
    Variation {
        name: "link byte drops",
        group: "link",
        change: "[sim] faults = \"drop=1e-4\"",
        basis: Basis::Estimate(
            "ten times the soak preset's byte loss: about one frame in 180 loses a byte and is re-synced",
        ),
        apply: |c| c.sim.faults = "drop=1e-4".into(),
    },
    Variation {
        name: "link bursts",
        group: "link",
        change: "[sim] faults = \"burst=0.01\"",
        basis: Basis::Estimate(
            "a late, bursty delivery (up to 300 ms held) every 1.5 s on average: a sluggish Bluetooth link",
        ),
        apply: |c| c.sim.faults = "burst=0.01".into(),
    },
];

/// One variation's outcome: the two effects the paper claims, from the stall study's own analysis.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// The variation's name.
    pub name: String,
    /// Its group.
    pub group: String,
    /// The change.
    pub change: String,
    /// Its basis.
    pub basis: Basis,
    /// Over-current observations, Pavlovian against reactive.
    pub overcurrent: Comparison,
    /// Efficiency (m/kJ), Pavlovian against reactive.
    pub efficiency: Comparison,
}

/// What the study writes into `variations.json`.
#[derive(Debug, Clone, Serialize)]
pub struct VariationsStudy {
    /// `stall-variations`.
    pub experiment: String,
    /// The options (per variation).
    pub options: StallOptions,
    /// How each run's seed is derived (the same for every variation).
    pub seed_derivation: String,
    /// The simulator seed of each planned run, by position.
    pub seeds: Vec<u64>,
    /// One row per variation, in [`VARIATIONS`] order.
    pub rows: Vec<Row>,
    /// Wall-clock time, s.
    pub wall_s: f64,
}

/// Runs every variation's study (never recorded) and analyses each with the stall study's statistics.
pub fn run_variations(
    base: &Config,
    opts: &StallOptions,
    variations: &[Variation],
    progress: bool,
) -> anyhow::Result<VariationsStudy> {
    let wall = Instant::now();
    let opts = StallOptions {
        record: false,
        ..opts.clone()
    };
    let configs = variations
        .iter()
        .map(|v| {
            let c = v.config(base);
            c.validate()
                .map_err(|e| anyhow::anyhow!("variation {:?}: {e}", v.name))?;
            Ok(c)
        })
        .collect::<anyhow::Result<Vec<Config>>>()?;
    let plans: Vec<Vec<RunSpec>> = configs.iter().map(|c| plan(c, &opts)).collect();
    let seeds: Vec<u64> = plans
        .first()
        .map(|p| p.iter().map(|s| s.seed).collect())
        .unwrap_or_default();
    let per = plans.first().map_or(0, Vec::len);
    // Interleaved across variations: run 0 of each, then run 1 of each, …
    let mut specs: Vec<(usize, RunSpec)> = Vec::with_capacity(per * plans.len());
    for i in 0..per {
        for (v, p) in plans.iter().enumerate() {
            if let Some(s) = p.get(i) {
                specs.push((v, s.clone()));
            }
        }
    }
    let bar = crate::experiment::progress_bar(specs.len(), progress);
    let on_done = |r: &(usize, RunResult)| {
        bar.inc(1);
        bar.set_message(format!(
            "{}: run {} {}",
            variations.get(r.0).map_or("", |v| v.name),
            r.1.index,
            r.1.mode.name()
        ));
    };
    let run_one = |(v, spec): &(usize, RunSpec)| {
        let config = configs.get(*v).unwrap_or(base);
        super::run::run(config, spec).map(|r| (*v, r))
    };
    let done = run_all(&specs, opts.threads, &run_one, &on_done)?;
    bar.finish_and_clear();
    let mut by_variation: Vec<Vec<RunResult>> = vec![Vec::new(); variations.len()];
    for (v, r) in done {
        if let Some(runs) = by_variation.get_mut(v) {
            runs.push(r);
        }
    }
    let mut rows = Vec::with_capacity(variations.len());
    for (v, mut runs) in variations.iter().zip(by_variation) {
        runs.sort_by_key(|r| r.index);
        let analysis = analyse(&runs, WINDOW_S);
        let find = |key: &str| {
            analysis
                .comparisons
                .iter()
                .find(|c| c.metric == key)
                .cloned()
                .ok_or_else(|| anyhow::anyhow!("the analysis has no {key}"))
        };
        rows.push(Row {
            name: v.name.into(),
            group: v.group.into(),
            change: v.change.into(),
            basis: v.basis,
            overcurrent: find("overcurrent_observations")?,
            efficiency: find("efficiency_m_per_kj")?,
        });
    }
    Ok(VariationsStudy {
        experiment: "stall-variations".into(),
        options: opts,
        seed_derivation: "run i of every variation uses the plain study's seed of run i: \
                          Rng::new(seed).fork(i).next_u64()"
            .into(),
        seeds,
        rows,
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

/// A relative change and its interval, in percent: `-49.1 % (-52.0, -46.3)`; `—` when undefined.
fn change_text(c: &Comparison) -> String {
    let Some(r) = c.relative_change else {
        return "—".into();
    };
    match c.relative_change_ci {
        Some((lo, hi)) if c.reactive.n > 1 && c.pavlovian.n > 1 => format!(
            "{:+.1} % ({:+.1}, {:+.1})",
            r * 100.0,
            lo * 100.0,
            hi * 100.0
        ),
        _ => format!("{:+.1} % (no interval)", r * 100.0),
    }
}

/// Where a change's interval lies: `below 0`, `above 0`, `across 0`, or `none`.
fn side(c: &Comparison) -> &'static str {
    match c.relative_change_ci {
        Some(_) if c.reactive.n < 2 || c.pavlovian.n < 2 => "none",
        Some((_, hi)) if hi < 0.0 => "below 0",
        Some((lo, _)) if lo > 0.0 => "above 0",
        Some(_) => "across 0",
        None => "none",
    }
}

fn n_text(c: &Comparison) -> String {
    format!("{} + {}", c.reactive.n, c.pavlovian.n)
}

/// For one claim (`sign` −1: a reduction, +1: an increase): in how many variations the interval lies on the
/// claimed side, and the others by name.
fn verdict(rows: &[Row], pick: fn(&Row) -> &Comparison, sign: f64, what: &str) -> String {
    let claimed = if sign < 0.0 { "below 0" } else { "above 0" };
    let held: Vec<&Row> = rows.iter().filter(|r| side(pick(r)) == claimed).collect();
    let others: Vec<String> = rows
        .iter()
        .filter(|r| side(pick(r)) != claimed)
        .map(|r| {
            let c = pick(r);
            format!(
                "{} ({}, {})",
                r.name,
                c.relative_change
                    .map_or("—".into(), |x| format!("{:+.1} %", x * 100.0)),
                side(c)
            )
        })
        .collect();
    let points: Vec<f64> = rows
        .iter()
        .filter_map(|r| pick(r).relative_change)
        .collect();
    let lo = points.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = points.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let range = if points.is_empty() {
        String::new()
    } else {
        format!(
            "; point estimates from {:+.1} % to {:+.1} %",
            lo * 100.0,
            hi * 100.0
        )
    };
    let rest = if others.is_empty() {
        String::new()
    } else {
        format!("; not in: {}", others.join(", "))
    };
    format!(
        "- {what}: the 95 % interval lies {claimed} in {} of {} variations{range}{rest}\n",
        held.len(),
        rows.len()
    )
}

/// The Markdown table, with a line per claim.
pub fn table(study: &VariationsStudy) -> String {
    let o = &study.options;
    let mut s = format!(
        "Robustness of the stall study: {} + {} interleaved runs × {} min per variation, seed {}, the same \
         run seeds in every variation; change = (Pavlovian − reactive) / reactive with the stall study's 95 % \
         bootstrap interval; n = reactive + Pavlovian runs.\n\n",
        o.runs_per_policy, o.runs_per_policy, o.minutes, o.seed
    );
    s.push_str(
        "| variation | group | change | source / estimate | over-current change (95 % CI) | efficiency \
         change (95 % CI) | n |\n|---|---|---|---|---|---|---|\n",
    );
    for r in &study.rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} |\n",
            r.name,
            r.group,
            r.change.replace('|', "\\|"),
            r.basis.label().replace('|', "\\|"),
            change_text(&r.overcurrent),
            change_text(&r.efficiency),
            n_text(&r.overcurrent)
        ));
    }
    s.push_str("\nThe paper's claims under variation:\n");
    s.push_str(&verdict(
        &study.rows,
        |r| &r.overcurrent,
        -1.0,
        "fewer over-current observations (paper −41 %)",
    ));
    s.push_str(&verdict(
        &study.rows,
        |r| &r.efficiency,
        1.0,
        "higher efficiency (paper +10 %)",
    ));
    s
}

fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

fn num(x: Option<f64>) -> String {
    x.map_or(String::new(), |v| format!("{v:.6}"))
}

/// The CSV table: one line per variation; relative changes as fractions.
pub fn csv(study: &VariationsStudy) -> String {
    let mut s = String::from(
        "variation,group,change,basis,basis_text,overcurrent_change,overcurrent_ci_lo,overcurrent_ci_hi,\
         efficiency_change,efficiency_ci_lo,efficiency_ci_hi,n_reactive,n_pavlovian\n",
    );
    for r in &study.rows {
        let (kind, text) = match r.basis {
            Basis::Source(t) => ("source", t),
            Basis::Estimate(t) => ("estimate", t),
        };
        let ci = |c: &Comparison| {
            let interval = c
                .relative_change_ci
                .filter(|_| c.reactive.n > 1 && c.pavlovian.n > 1);
            (num(interval.map(|i| i.0)), num(interval.map(|i| i.1)))
        };
        let (olo, ohi) = ci(&r.overcurrent);
        let (elo, ehi) = ci(&r.efficiency);
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            csv_field(&r.name),
            csv_field(&r.group),
            csv_field(&r.change),
            kind,
            csv_field(text),
            num(r.overcurrent.relative_change),
            olo,
            ohi,
            num(r.efficiency.relative_change),
            elo,
            ehi,
            r.overcurrent.reactive.n,
            r.overcurrent.pavlovian.n
        ));
    }
    s
}

/// Writes `variations.md`, `variations.csv`, `variations.json` and `fig_variations.{svg,png}` into `dir`.
pub fn write_all(dir: &Path, study: &VariationsStudy) -> anyhow::Result<()> {
    use anyhow::Context;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let write = |name: &str, text: String| {
        std::fs::write(dir.join(name), text)
            .with_context(|| format!("cannot write {}", dir.join(name).display()))
    };
    write("variations.md", table(study))?;
    write("variations.csv", csv(study))?;
    write("variations.json", serde_json::to_string_pretty(study)?)?;
    super::variations_forest::forest(dir, study).context("cannot draw fig_variations")?;
    Ok(())
}

/// Runs the robustness study with every [`VARIATIONS`], writes its files into `opts.out` and returns the
/// terminal table.
pub fn run_and_report(
    base: &Config,
    opts: &StallOptions,
    progress: bool,
) -> anyhow::Result<String> {
    let study = run_variations(base, opts, &VARIATIONS, progress)?;
    write_all(&opts.out, &study)?;
    let mut t = table(&study);
    t.push_str(&format!(
        "results: {} ({:.0} s wall)\n",
        opts.out.display(),
        study.wall_s
    ));
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> Config {
        Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap()
    }

    #[test]
    fn every_variation_is_named_once_has_a_basis_and_changes_only_its_part() {
        let base = base();
        let mut names: Vec<&str> = VARIATIONS.iter().map(|v| v.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), VARIATIONS.len());
        assert_eq!(
            VARIATIONS[0].config(&base),
            base,
            "the baseline is the base"
        );
        for v in &VARIATIONS[1..] {
            let c = v.config(&base);
            assert_ne!(c, base, "{} changes something", v.name);
            c.validate().unwrap_or_else(|e| panic!("{}: {e}", v.name));
            let text = match v.basis {
                Basis::Source(t) | Basis::Estimate(t) => t,
            };
            assert!(!text.is_empty());
            // Only the simulation or the default policy changes; learning and the gate never.
            assert_eq!(c.predictions, base.predictions, "{}", v.name);
            assert_eq!(c.control.stimulus, base.control.stimulus);
            assert_eq!(c.control.response, base.control.response);
            assert_eq!(c.sim.seed, base.sim.seed);
        }
        let groups = ["reading", "world", "robot", "sensing", "policy", "link"];
        for g in groups {
            assert!(VARIATIONS.iter().any(|v| v.group == g), "{g}");
        }
    }

    #[test]
    fn the_speed_variations_slow_the_straights_alone_or_the_whole_cycle() {
        let base = base();
        let policy = |name: &str| {
            VARIATIONS
                .iter()
                .find(|v| v.name == name)
                .map(|v| v.config(&base).control.default_policy)
                .unwrap_or_else(|| panic!("no variation {name}"))
        };
        let cycle = |drive_mm_s, turn_mm_s| Policy::StallCycle {
            drive_mm_s,
            turn_mm_s,
        };
        assert_eq!(policy("straight 100 mm/s"), cycle(100, 100));
        assert_eq!(policy("straight 300 mm/s"), cycle(300, 100));
        assert_eq!(policy("cycle 100 mm/s"), cycle(100, 50));
        assert_eq!(policy("cycle 300 mm/s"), cycle(300, 150));
        // The cycle variations keep the default's ratio of turn to straight speed.
        assert_eq!(
            base.control.default_policy,
            cycle(
                pavlov::control::policy::STALL_DRIVE_MM_S,
                pavlov::control::policy::STALL_TURN_MM_S
            )
        );
    }

    #[test]
    fn verdicts_read_the_intervals() {
        use pavlov::analysis::stats::describe;
        let cmp = |r: f64, ci: (f64, f64)| Comparison {
            metric: "m".into(),
            label: "m".into(),
            unit: "u".into(),
            reactive: describe(&[1.0, 2.0]),
            pavlovian: describe(&[1.0, 2.0]),
            relative_change: Some(r),
            relative_change_ci: Some(ci),
            reactive_range: None,
            pavlovian_range: None,
            welch: None,
        };
        let row = |name: &str, e: (f64, (f64, f64))| Row {
            name: name.into(),
            group: "g".into(),
            change: "c".into(),
            basis: Basis::Estimate("x"),
            overcurrent: cmp(-0.4, (-0.5, -0.3)),
            efficiency: cmp(e.0, e.1),
        };
        let rows = vec![row("a", (0.3, (0.2, 0.4))), row("b", (0.05, (-0.1, 0.2)))];
        let v = verdict(&rows, |r| &r.efficiency, 1.0, "eff");
        assert!(v.contains("above 0 in 1 of 2"), "{v}");
        assert!(v.contains("not in: b (+5.0 %, across 0)"), "{v}");
        let o = verdict(&rows, |r| &r.overcurrent, -1.0, "oc");
        assert!(
            o.contains("below 0 in 2 of 2") && !o.contains("not in"),
            "{o}"
        );
    }
}
