//! A strict reader of the Prometheus text exposition format (0.0.4), for checking what `/metrics` serves:
//! in unit tests of `super::prometheus` and in the end-to-end tests, which read a live server's text.
//!
//! `parse` refuses what a scraper would refuse or misread: invalid metric or label names, bad escapes or
//! values, a sample without `# HELP` and `# TYPE` before it, a family split in two, a negative counter, and a
//! histogram whose buckets are not cumulative, do not end at `+Inf`, or whose `+Inf` differs from `_count`.

use std::collections::BTreeMap;

/// One sample line.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// The sample's name (for a histogram: `<family>_bucket`, `_sum` or `_count`).
    pub name: String,
    /// Its labels.
    pub labels: BTreeMap<String, String>,
    /// Its value.
    pub value: f64,
}

/// A metric family: its `# HELP`, `# TYPE` and samples.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Family {
    /// `counter`, `gauge`, `histogram`, `summary` or `untyped`.
    pub kind: String,
    /// The help text.
    pub help: String,
    /// The samples, in order.
    pub samples: Vec<Sample>,
}

/// Whether `name` is a valid metric name (`[a-zA-Z_:][a-zA-Z0-9_:]*`).
pub(crate) fn valid_metric_name(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_' || c == ':')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':')
}

fn valid_label_name(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn parse_value(text: &str) -> Result<f64, String> {
    match text {
        "+Inf" => Ok(f64::INFINITY),
        "-Inf" => Ok(f64::NEG_INFINITY),
        "NaN" => Ok(f64::NAN),
        t => t.parse().map_err(|_| format!("bad value `{t}`")),
    }
}

/// Parses `{k="v",…}` at the start of `rest`; returns the labels and what follows the `}`.
fn parse_labels(rest: &str) -> Result<(BTreeMap<String, String>, &str), String> {
    let mut labels = BTreeMap::new();
    let mut s = rest;
    loop {
        s = s.trim_start();
        if let Some(after) = s.strip_prefix('}') {
            return Ok((labels, after));
        }
        let (name, after) = s
            .split_once('=')
            .ok_or_else(|| format!("label without `=` in `{rest}`"))?;
        let name = name.trim();
        if !valid_label_name(name) {
            return Err(format!("bad label name `{name}`"));
        }
        let mut chars = after
            .strip_prefix('"')
            .ok_or_else(|| format!("label `{name}` is not quoted"))?
            .char_indices();
        let mut value = String::new();
        let end = loop {
            match chars.next() {
                Some((i, '"')) => break i,
                Some((_, '\\')) => match chars.next() {
                    Some((_, '\\')) => value.push('\\'),
                    Some((_, '"')) => value.push('"'),
                    Some((_, 'n')) => value.push('\n'),
                    other => return Err(format!("bad escape {other:?} in label `{name}`")),
                },
                Some((_, c)) => value.push(c),
                None => return Err(format!("unterminated value of label `{name}`")),
            }
        };
        if labels.insert(name.to_string(), value).is_some() {
            return Err(format!("label `{name}` twice"));
        }
        s = &after[1 + end + 1..];
        s = s.trim_start();
        if let Some(after_comma) = s.strip_prefix(',') {
            s = after_comma;
        }
    }
}

fn parse_sample(line: &str) -> Result<Sample, String> {
    let name_end = line.find(['{', ' ']).unwrap_or(line.len());
    let name = &line[..name_end];
    if !valid_metric_name(name) {
        return Err(format!("bad metric name `{name}`"));
    }
    let (labels, rest) = match line[name_end..].strip_prefix('{') {
        Some(inner) => parse_labels(inner)?,
        None => (BTreeMap::new(), &line[name_end..]),
    };
    let mut fields = rest.split_whitespace();
    let value = parse_value(fields.next().ok_or_else(|| format!("no value: `{line}`"))?)?;
    if let Some(ts) = fields.next() {
        ts.parse::<i64>()
            .map_err(|_| format!("bad timestamp `{ts}`"))?;
    }
    if fields.next().is_some() {
        return Err(format!("trailing text: `{line}`"));
    }
    Ok(Sample {
        name: name.to_string(),
        labels,
        value,
    })
}

/// The family a sample belongs to, given the families declared so far.
fn family_of<'a>(name: &'a str, families: &BTreeMap<String, Family>) -> &'a str {
    for suffix in ["_bucket", "_sum", "_count"] {
        if let Some(base) = name.strip_suffix(suffix)
            && families.get(base).is_some_and(|f| f.kind == "histogram")
        {
            return base;
        }
    }
    name
}

fn check_histogram(name: &str, f: &Family) -> Result<(), String> {
    let mut last_le = f64::NEG_INFINITY;
    let mut last_count = 0.0;
    let mut inf = None;
    for s in f.samples.iter().filter(|s| s.name.ends_with("_bucket")) {
        let le = s
            .labels
            .get("le")
            .ok_or_else(|| format!("{name}: a bucket without `le`"))
            .and_then(|le| parse_value(le))?;
        if le <= last_le || s.value < last_count {
            return Err(format!(
                "{name}: bucket le={le} ({}) after le={last_le} ({last_count})",
                s.value
            ));
        }
        last_le = le;
        last_count = s.value;
        if le == f64::INFINITY {
            inf = Some(s.value);
        }
    }
    let count = f
        .samples
        .iter()
        .find(|s| s.name == format!("{name}_count"))
        .ok_or_else(|| format!("{name}: no _count"))?;
    if !f.samples.iter().any(|s| s.name == format!("{name}_sum")) {
        return Err(format!("{name}: no _sum"));
    }
    match inf {
        Some(v) if v == count.value => Ok(()),
        Some(v) => Err(format!("{name}: +Inf bucket {v} ≠ _count {}", count.value)),
        None => Err(format!("{name}: no +Inf bucket")),
    }
}

/// Parses and checks an exposition; the families by name.
pub fn parse(text: &str) -> Result<BTreeMap<String, Family>, String> {
    if !text.is_empty() && !text.ends_with('\n') {
        return Err("the text does not end with a newline".into());
    }
    let mut families: BTreeMap<String, Family> = BTreeMap::new();
    let mut current: Option<String> = None;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        if let Some(comment) = line.strip_prefix('#') {
            let mut words = comment.trim_start().splitn(3, ' ');
            let (Some(keyword @ ("HELP" | "TYPE")), Some(name)) = (words.next(), words.next())
            else {
                continue;
            };
            if !valid_metric_name(name) {
                return Err(format!("bad metric name `{name}` in `{line}`"));
            }
            let rest = words.next().unwrap_or("").to_string();
            let f = families.entry(name.to_string()).or_default();
            if !f.samples.is_empty() {
                return Err(format!("`{line}` after the samples of {name}"));
            }
            if keyword == "HELP" {
                f.help = rest;
            } else if !f.kind.is_empty() {
                return Err(format!("a second TYPE for {name}"));
            } else if ["counter", "gauge", "histogram", "summary", "untyped"]
                .contains(&rest.as_str())
            {
                f.kind = rest;
            } else {
                return Err(format!("unknown type `{rest}` of {name}"));
            }
            continue;
        }
        let sample = parse_sample(line)?;
        let family = family_of(&sample.name, &families).to_string();
        let f = families
            .get_mut(&family)
            .ok_or_else(|| format!("`{}` has no # HELP / # TYPE", sample.name))?;
        if f.kind.is_empty() || f.help.is_empty() {
            return Err(format!("{family} lacks # HELP or # TYPE"));
        }
        if current.as_deref() != Some(family.as_str()) && !f.samples.is_empty() {
            return Err(format!("the samples of {family} are split"));
        }
        if f.kind == "counter" && (sample.value.is_nan() || sample.value < 0.0) {
            return Err(format!("counter {} is {}", sample.name, sample.value));
        }
        current = Some(family);
        f.samples.push(sample);
    }
    for (name, f) in &families {
        if f.kind == "histogram" {
            check_histogram(name, f)?;
        }
    }
    Ok(families)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# HELP a_total A.\n# TYPE a_total counter\na_total 3\n\
        # HELP h H.\n# TYPE h histogram\nh_bucket{le=\"0.1\"} 1\nh_bucket{le=\"+Inf\"} 2\nh_sum 0.3\nh_count 2\n";

    #[test]
    fn a_good_exposition_parses() {
        let f = parse(GOOD).unwrap();
        assert_eq!(f["a_total"].samples[0].value, 3.0);
        assert_eq!(f["h"].samples.len(), 4);
        assert_eq!(f["h"].samples[0].labels["le"], "0.1");
    }

    #[test]
    fn every_kind_of_mistake_is_refused() {
        let bad = [
            GOOD.replace("# HELP a_total A.\n", ""),
            GOOD.replace("# TYPE a_total counter\n", ""),
            GOOD.replace("a_total 3", "a-total 3"),
            GOOD.replace("a_total 3", "a_total -3"),
            GOOD.replace("a_total 3", "a_total three"),
            GOOD.replace("h_bucket{le=\"0.1\"} 1", "h_bucket{le=\"0.1\"} 3"),
            GOOD.replace("h_count 2", "h_count 5"),
            GOOD.replace("h_bucket{le=\"+Inf\"} 2\n", ""),
            GOOD.replace("h_sum 0.3\n", ""),
            GOOD.replace("{le=\"0.1\"}", "{le=0.1}"),
            GOOD.replace("{le=\"0.1\"}", "{2le=\"0.1\"}"),
            format!("{GOOD}a_total 4\n"),
            GOOD.trim_end().to_string(),
        ];
        for text in bad {
            assert!(parse(&text).is_err(), "accepted:\n{text}");
        }
    }
}
