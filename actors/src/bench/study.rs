//! `pavlov bench --virtual-time`: the stall study (the paper's default: 10 + 10 runs of 6 minutes, with
//! recordings) timed per simulated tick, in CPU time (user + system, of the whole process) beside wall
//! time. CPU time is what a change to the virtual-time path saves; wall time on a shared machine mostly
//! measures the load, which the report prints at the start and at the end.

use std::fmt;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use pavlov::config::Config;

use crate::experiment::stall::{self, StallOptions};

/// CPU time the process has used so far (user, system), from `getrusage`.
pub fn process_cpu() -> std::io::Result<(Duration, Duration)> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: `getrusage` writes a `rusage` into the valid, writable, properly aligned buffer it is given
    // and reads nothing from it; RUSAGE_SELF names the calling process.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: the call succeeded, so it has written the whole struct (and zeroed() initialised it anyway).
    let usage = unsafe { usage.assume_init() };
    let time = |t: libc::timeval| {
        Duration::from_secs(u64::try_from(t.tv_sec).unwrap_or(0))
            + Duration::from_micros(u64::try_from(t.tv_usec).unwrap_or(0))
    };
    Ok((time(usage.ru_utime), time(usage.ru_stime)))
}

/// One timed study.
#[derive(Debug, Clone)]
pub struct StudyTiming {
    /// Runs (both policies).
    pub runs: usize,
    /// Simulated ticks, all runs together.
    pub ticks: u64,
    /// Whether every run was recorded.
    pub recorded: bool,
    /// OS threads the runs were spread over.
    pub threads: usize,
    /// User CPU time.
    pub user: Duration,
    /// System CPU time.
    pub system: Duration,
    /// Wall-clock time.
    pub wall: Duration,
    /// Simulated time, all runs together.
    pub simulated: Duration,
    /// The 1-minute load average before and after.
    pub load: (Option<f64>, Option<f64>),
}

impl StudyTiming {
    /// CPU time (user + system) per simulated tick, µs.
    pub fn cpu_us_per_tick(&self) -> f64 {
        (self.user + self.system).as_secs_f64() * 1e6 / self.ticks.max(1) as f64
    }

    /// Wall time per simulated tick, µs.
    pub fn wall_us_per_tick(&self) -> f64 {
        self.wall.as_secs_f64() * 1e6 / self.ticks.max(1) as f64
    }
}

impl fmt::Display for StudyTiming {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let load = |l: Option<f64>| l.map_or("?".into(), |l| format!("{l:.2}"));
        writeln!(
            f,
            "stall study: {} runs, {} simulated ticks ({:.0} s simulated), {}, {} thread(s); \
             load average {} → {}",
            self.runs,
            self.ticks,
            self.simulated.as_secs_f64(),
            if self.recorded {
                "recorded"
            } else {
                "not recorded"
            },
            self.threads,
            load(self.load.0),
            load(self.load.1)
        )?;
        writeln!(f, "{:<24}{:>12}{:>16}", "", "total s", "µs per tick")?;
        let cpu = self.user + self.system;
        for (name, d) in [
            ("CPU (user + system)", cpu),
            ("  user", self.user),
            ("  system", self.system),
            ("wall", self.wall),
        ] {
            writeln!(
                f,
                "{:<24}{:>12.2}{:>16.2}",
                name,
                d.as_secs_f64(),
                d.as_secs_f64() * 1e6 / self.ticks.max(1) as f64
            )?;
        }
        write!(
            f,
            "simulated time per CPU second: {:.0}×; per wall second: {:.0}×",
            self.simulated.as_secs_f64() / cpu.as_secs_f64().max(1e-9),
            self.simulated.as_secs_f64() / self.wall.as_secs_f64().max(1e-9)
        )
    }
}

/// Runs the stall study of `runs_per_policy` pairs of `minutes` with `config` on `threads` threads,
/// recorded into `scratch` when it is given, and times it. The study's files are written into `scratch`
/// too; the caller removes them.
pub fn time_stall_study(
    config: &Config,
    runs_per_policy: usize,
    minutes: f64,
    threads: usize,
    scratch: Option<PathBuf>,
) -> anyhow::Result<StudyTiming> {
    let opts = StallOptions {
        runs_per_policy,
        minutes,
        seed: 1,
        record: scratch.is_some(),
        threads,
        out: scratch.unwrap_or_default(),
    };
    let runs = stall::plan(config, &opts);
    let ticks = runs.iter().map(|r| r.ticks).sum::<u64>();
    let load_before = super::load_average();
    let (u0, s0) = process_cpu()?;
    let wall = Instant::now();
    stall::run_study(config, &opts, false)?;
    let wall = wall.elapsed();
    let (u1, s1) = process_cpu()?;
    Ok(StudyTiming {
        runs: runs.len(),
        ticks,
        recorded: opts.record,
        threads,
        user: u1.saturating_sub(u0),
        system: s1.saturating_sub(s0),
        wall,
        simulated: Duration::from_millis(ticks * config.tick.period_ms),
        load: (load_before, super::load_average()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn process_cpu_time_grows_with_work() {
        let (u0, s0) = process_cpu().unwrap();
        // Spin until the clock (10 ms resolution at worst) has moved: bounded by what it observes.
        let mut x = 0u64;
        loop {
            for i in 0..100_000u64 {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(i);
            }
            let (u, s) = process_cpu().unwrap();
            if u + s > u0 + s0 {
                break;
            }
        }
        assert_ne!(std::hint::black_box(x), 1);
    }
}
