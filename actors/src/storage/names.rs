//! Plain names: what a websocket client may call a file or folder the server creates for it
//! (`save_weights`, `start_recording`). A client names a thing, never a place: the server decides the
//! folder, and a name can neither climb out of it (`..`, `/`, an absolute path), nor hide (`.x`), nor
//! grow without bound.

/// The longest plain name, in bytes.
pub(crate) const MAX_NAME_LEN: usize = 100;

/// The rules, as the error replies state them.
pub(crate) const NAME_RULES: &str = "a plain name: letters, digits, '.', '_' and '-', \
     at most 100 characters, no '/' or '\\', no '..', not absolute, not starting with '.'";

/// Why a name is not plain; each message names the rule it breaks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum NameError {
    #[error("the name is empty")]
    Empty,
    #[error("`{0}` is an absolute path")]
    Absolute(String),
    #[error("`{0}` contains a path separator")]
    Separator(String),
    #[error("`{0}` contains `..`")]
    ParentDir(String),
    #[error("`{0}` is hidden (starts with '.')")]
    Hidden(String),
    #[error("`{name}` is {len} characters long, more than {MAX_NAME_LEN}")]
    TooLong { name: String, len: usize },
    #[error("`{name}` contains {found:?}")]
    Character { name: String, found: char },
}

/// Checks that `name` is a plain name ([`NAME_RULES`]).
pub(crate) fn check_plain_name(name: &str) -> Result<(), NameError> {
    let owned = || shorten(name);
    if name.is_empty() {
        return Err(NameError::Empty);
    }
    if name.starts_with(['/', '\\']) || name.as_bytes().get(1) == Some(&b':') {
        return Err(NameError::Absolute(owned()));
    }
    if name.contains(['/', '\\']) {
        return Err(NameError::Separator(owned()));
    }
    if name.contains("..") {
        return Err(NameError::ParentDir(owned()));
    }
    if name.starts_with('.') {
        return Err(NameError::Hidden(owned()));
    }
    if name.len() > MAX_NAME_LEN {
        return Err(NameError::TooLong {
            name: owned(),
            len: name.len(),
        });
    }
    if let Some(found) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-')))
    {
        return Err(NameError::Character {
            name: owned(),
            found,
        });
    }
    Ok(())
}

/// `name` cut to a length fit for an error message.
fn shorten(name: &str) -> String {
    const SHOWN: usize = 120;
    match name.char_indices().nth(SHOWN) {
        Some((at, _)) => format!("{}…", &name[..at]),
        None => name.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_pass() {
        for ok in [
            "w.json",
            "run-3_weights.json",
            "a",
            "recording-20261124T013000Z",
        ] {
            assert_eq!(check_plain_name(ok), Ok(()), "{ok}");
        }
        assert_eq!(check_plain_name(&"x".repeat(MAX_NAME_LEN)), Ok(()));
    }

    #[test]
    fn every_rule_is_named() {
        let cases: [(&str, &str); 10] = [
            ("", "empty"),
            ("/tmp/x", "absolute"),
            ("C:x", "absolute"),
            ("../x", "separator"),
            ("a/b", "separator"),
            ("a\\b", "separator"),
            ("..", "`..`"),
            (".hidden", "hidden"),
            ("x y", "contains ' '"),
            ("ü.json", "contains 'ü'"),
        ];
        for (name, rule) in cases {
            let msg = check_plain_name(name).unwrap_err().to_string();
            assert!(msg.contains(rule), "{name}: {msg}");
        }
        let long = "x".repeat(MAX_NAME_LEN + 1);
        let msg = check_plain_name(&long).unwrap_err().to_string();
        assert!(msg.contains("101 characters long, more than 100"), "{msg}");
    }
}
