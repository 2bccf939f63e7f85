//! Provenance: which code, built how, run with which command line and configuration, made an artifact.
//!
//! [`BUILD`] is fixed at compile time by `actors/build.rs` (the git commit and whether the tree differed
//! from it, the cargo features, the compiler, the target, the profile). [`Provenance::of`] adds what only
//! the running process knows: its command line (with any token replaced by
//! [`REDACTED`]) and a SHA-256 of the configuration in force (redacted too, so the
//! hash cannot be used to test guesses of the token). Every recording's metadata, every study's
//! `summary.json`, `policies.json` and shard file, and `pavlov --version` carry it.

use pavlov::config::{Config, REDACTED};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// What the build fixed.
#[derive(Debug, Clone, Copy)]
pub struct Build {
    /// The package version (`0.1.0`).
    pub version: &'static str,
    /// The git commit the binary was built from, or `unknown` (built outside a git checkout).
    pub commit: &'static str,
    /// `true`, `false`, or `unknown` (no git): whether the checkout differed from that commit.
    pub dirty: &'static str,
    /// The cargo features of the `pavlov-actors` package, comma-separated.
    pub features: &'static str,
    /// `rustc --version` of the compiler.
    pub rustc: &'static str,
    /// The target triple.
    pub target: &'static str,
    /// `debug` or `release`.
    pub profile: &'static str,
}

/// This binary's build.
pub const BUILD: Build = Build {
    version: env!("CARGO_PKG_VERSION"),
    commit: env!("PAVLOV_GIT_COMMIT"),
    dirty: env!("PAVLOV_GIT_DIRTY"),
    features: env!("PAVLOV_FEATURES"),
    rustc: env!("PAVLOV_RUSTC"),
    target: env!("PAVLOV_TARGET"),
    profile: env!("PAVLOV_PROFILE"),
};

impl Build {
    /// `pavlov 0.1.0 (1a2b3c4d5e6f, dirty)`: the program name recordings have always carried, now naming
    /// the commit (12 hex digits) and whether the tree was dirty.
    pub fn program(&self) -> String {
        let short: String = self.commit.chars().take(12).collect();
        let state = match self.dirty {
            "true" => ", dirty",
            "false" => "",
            _ => ", dirty state unknown",
        };
        format!("pavlov {} ({short}{state})", self.version)
    }

    /// What `pavlov --version` prints after the name: version, then one `key: value` line per field.
    pub fn long_version(&self) -> String {
        format!(
            "{}\ncommit: {}\ndirty: {}\nfeatures: {}\nrustc: {}\ntarget: {}\nprofile: {}",
            self.version,
            self.commit,
            self.dirty,
            if self.features.is_empty() {
                "(none)"
            } else {
                self.features
            },
            self.rustc,
            self.target,
            self.profile
        )
    }
}

/// Everything an artifact says about where it came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance {
    /// `pavlov <version> (<commit>[, dirty])`.
    pub program: String,
    /// The package version.
    pub version: String,
    /// The full git commit, or `unknown`.
    pub commit: String,
    /// `true`, `false` or `unknown`.
    pub dirty: String,
    /// The cargo features, comma-separated.
    pub features: String,
    /// `rustc --version`.
    pub rustc: String,
    /// The target triple.
    pub target: String,
    /// The build profile.
    pub profile: String,
    /// The process's command line, tokens redacted.
    pub command_line: Vec<String>,
    /// `sha256:` and the hex SHA-256 of the configuration in force (redacted) as canonical JSON
    /// ([`json_sha256`]); empty where an artifact belongs to no one configuration.
    pub config_sha256: String,
}

impl Provenance {
    /// The provenance of an artifact made by this process under `config`.
    pub fn of(config: &Config) -> Self {
        Self::of_json_config(&serde_json::to_value(config.redacted()).unwrap_or_default())
    }

    /// The same for a configuration already in JSON (a shard file's, redacted when it was written).
    pub fn of_json_config(config: &serde_json::Value) -> Self {
        Provenance {
            config_sha256: json_sha256(config),
            ..Provenance::of_process()
        }
    }

    /// The provenance of an artifact that belongs to no one configuration (a study's summary: each run's
    /// configuration hash is in its recording and in its shard file); `config_sha256` is empty.
    pub fn of_process() -> Self {
        let b = BUILD;
        Provenance {
            program: b.program(),
            version: b.version.to_string(),
            commit: b.commit.to_string(),
            dirty: b.dirty.to_string(),
            features: b.features.to_string(),
            rustc: b.rustc.to_string(),
            target: b.target.to_string(),
            profile: b.profile.to_string(),
            command_line: redact_args(
                std::env::args_os().map(|a| a.to_string_lossy().into_owned()),
            ),
            config_sha256: String::new(),
        }
    }

    /// As MCAP metadata (every value a string): the keys of this struct, `command_line` as a JSON array.
    pub fn to_metadata(&self) -> Vec<(&'static str, String)> {
        vec![
            ("version", self.version.clone()),
            ("commit", self.commit.clone()),
            ("dirty", self.dirty.clone()),
            ("features", self.features.clone()),
            ("rustc", self.rustc.clone()),
            ("target", self.target.clone()),
            ("profile", self.profile.clone()),
            (
                "command_line",
                serde_json::to_string(&self.command_line).unwrap_or_default(),
            ),
            ("config_sha256", self.config_sha256.clone()),
        ]
    }

    /// Back from MCAP metadata (`program` is its own key there); `None` when the recording predates
    /// provenance (it has no `commit` key).
    pub fn from_metadata(program: &str, get: impl Fn(&str) -> Option<String>) -> Option<Self> {
        let commit = get("commit")?;
        let text = |k: &str| get(k).unwrap_or_default();
        Some(Provenance {
            program: program.to_string(),
            version: text("version"),
            commit,
            dirty: text("dirty"),
            features: text("features"),
            rustc: text("rustc"),
            target: text("target"),
            profile: text("profile"),
            command_line: get("command_line")
                .and_then(|s| serde_json::from_str(&s).ok())
                .unwrap_or_default(),
            config_sha256: text("config_sha256"),
        })
    }

    /// Whether this artifact was made by a build of another commit than this binary's (both known).
    pub fn other_commit(&self) -> Option<&str> {
        let known = |c: &str| !c.is_empty() && c != "unknown";
        (known(&self.commit) && known(BUILD.commit) && self.commit != BUILD.commit)
            .then_some(self.commit.as_str())
    }
}

/// Options whose value is a secret (`--token T` or `--token=T`).
const SECRET_OPTIONS: &[&str] = &["--token"];

/// `args` with the value of every secret option replaced by [`REDACTED`].
pub fn redact_args(args: impl IntoIterator<Item = String>) -> Vec<String> {
    let mut out = Vec::new();
    let mut secret_next = false;
    for arg in args {
        if secret_next {
            out.push(REDACTED.to_string());
            secret_next = false;
            continue;
        }
        if let Some(opt) = SECRET_OPTIONS
            .iter()
            .find(|o| arg.strip_prefix(**o).is_some_and(|r| r.starts_with('=')))
        {
            out.push(format!("{opt}={REDACTED}"));
            continue;
        }
        secret_next = SECRET_OPTIONS.contains(&arg.as_str());
        out.push(arg);
    }
    out
}

/// `sha256:<hex>` of `config`, redacted, as canonical JSON ([`json_sha256`]).
pub fn config_sha256(config: &Config) -> String {
    json_sha256(&serde_json::to_value(config.redacted()).unwrap_or_default())
}

/// `sha256:<hex>` of `value` as canonical JSON: compact, object keys in byte order at every depth, so
/// the same configuration hashes the same whichever way it was built or read back (a shard file's
/// configuration is the same hash as the recording's).
pub fn json_sha256(value: &serde_json::Value) -> String {
    let mut canonical = Vec::new();
    write_canonical(value, &mut canonical);
    let digest = Sha256::digest(&canonical);
    let mut hex = String::with_capacity(7 + 64);
    hex.push_str("sha256:");
    for b in digest {
        hex.push_str(&format!("{b:02x}"));
    }
    hex
}

fn write_canonical(value: &serde_json::Value, out: &mut Vec<u8>) {
    use serde_json::Value;
    match value {
        Value::Object(map) => {
            let mut entries: Vec<_> = map.iter().collect();
            entries.sort_by(|a, b| a.0.cmp(b.0));
            out.push(b'{');
            for (i, (k, v)) in entries.into_iter().enumerate() {
                if i > 0 {
                    out.push(b',');
                }
                out.extend(serde_json::to_vec(k).unwrap_or_default());
                out.push(b':');
                write_canonical(v, out);
            }
            out.push(b'}');
        }
        Value::Array(items) => {
            out.push(b'[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    out.push(b',');
                }
                write_canonical(v, out);
            }
            out.push(b']');
        }
        scalar => out.extend(serde_json::to_vec(scalar).unwrap_or_default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &[&str]) -> Vec<String> {
        s.iter().map(|a| a.to_string()).collect()
    }

    #[test]
    fn a_token_on_the_command_line_is_redacted_in_both_spellings() {
        let got = redact_args(args(&[
            "pavlov",
            "serve",
            "--token",
            "s3cret",
            "--token=s3cret",
            "--record",
            "r",
        ]));
        assert_eq!(
            got,
            args(&[
                "pavlov",
                "serve",
                "--token",
                REDACTED,
                "--token=<redacted>",
                "--record",
                "r"
            ])
        );
        // A trailing `--token` without a value, and look-alike options, are left as they are.
        assert_eq!(redact_args(args(&["--token"])), args(&["--token"]));
        assert_eq!(
            redact_args(args(&["--tokens", "x"])),
            args(&["--tokens", "x"])
        );
    }

    #[test]
    fn the_config_hash_ignores_the_token_and_sees_everything_else() {
        let text = include_str!("../../config/stall.toml");
        let a = Config::from_toml(text).expect("stall.toml");
        let mut b = a.clone();
        b.dashboard.token = Some("0123456789abcdef0123".into());
        let mut c = a.clone();
        c.dashboard.token = Some("another-token-entirely".into());
        assert_eq!(
            config_sha256(&b),
            config_sha256(&c),
            "the token is not hashed"
        );
        let mut d = a.clone();
        d.sim.seed += 1;
        assert_ne!(config_sha256(&a), config_sha256(&d));
        assert_eq!(config_sha256(&a), config_sha256(&a.clone()));
        assert!(config_sha256(&a).starts_with("sha256:") && config_sha256(&a).len() == 71);
    }

    #[test]
    fn canonical_json_ignores_key_order_only() {
        let a: serde_json::Value =
            serde_json::from_str(r#"{"b":1,"a":{"y":[1,2],"x":"s"}}"#).unwrap();
        let b: serde_json::Value =
            serde_json::from_str(r#"{"a":{"x":"s","y":[1,2]},"b":1}"#).unwrap();
        let c: serde_json::Value =
            serde_json::from_str(r#"{"a":{"x":"s","y":[2,1]},"b":1}"#).unwrap();
        assert_eq!(json_sha256(&a), json_sha256(&b));
        assert_ne!(json_sha256(&a), json_sha256(&c));
        // The digest of `{}` is SHA-256 of the two bytes "{}".
        assert_eq!(
            json_sha256(&serde_json::json!({})),
            "sha256:44136fa355b3678a1146ad16f7e8649e94fb4fc21fe77e8310c060f61caaff8a"
        );
    }

    #[test]
    fn metadata_round_trips() {
        let text = include_str!("../../config/stall.toml");
        let p = Provenance::of(&Config::from_toml(text).expect("stall.toml"));
        let map: std::collections::BTreeMap<_, _> = p.to_metadata().into_iter().collect();
        let back = Provenance::from_metadata(&p.program, |k| map.get(k).cloned());
        assert_eq!(back.as_ref(), Some(&p));
        assert_eq!(Provenance::from_metadata("old", |_| None), None);
    }

    #[test]
    fn the_build_names_a_commit() {
        assert!(
            BUILD.commit == "unknown" || BUILD.commit.len() >= 40,
            "{}",
            BUILD.commit
        );
        assert!(["true", "false", "unknown"].contains(&BUILD.dirty));
        assert!(BUILD.program().starts_with("pavlov "));
        assert!(BUILD.long_version().contains("commit: "));
    }
}
