//! `results/<name>-latest`: a relative symbolic link to the newest default folder of a kind of study, so
//! commands that look for "the last stall study" still find it. It is replaced atomically: a new link is
//! made under a temporary name beside it and renamed over the old one, so a reader sees the old link or the
//! new one, never none. Anything at that name that is not a symbolic link is left alone (and reported).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::ResultsError;

/// The name of the link for studies named `name`.
pub fn link_name(name: &str) -> String {
    format!("{name}-latest")
}

/// Points `root/<name>-latest` at `root/<target>` (a relative link, so the folder can be moved whole);
/// returns the link's path.
pub fn point(root: &Path, name: &str, target: &str) -> Result<PathBuf, ResultsError> {
    static MADE: AtomicU64 = AtomicU64::new(0);
    let link = root.join(link_name(name));
    if let Ok(meta) = std::fs::symlink_metadata(&link)
        && !meta.file_type().is_symlink()
    {
        return Err(ResultsError::Io {
            path: link,
            source: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "it exists and is not a symbolic link, so it is left as it is",
            ),
        });
    }
    let n = MADE.fetch_add(1, Ordering::Relaxed);
    let tmp = root.join(format!(
        ".{}.tmp-{}-{n}",
        link_name(name),
        std::process::id()
    ));
    std::os::unix::fs::symlink(target, &tmp).map_err(ResultsError::io(&tmp))?;
    std::fs::rename(&tmp, &link).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        ResultsError::Io {
            path: link.clone(),
            source,
        }
    })?;
    Ok(link)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_link_is_relative_and_replaced_and_a_real_folder_is_left_alone() {
        let root = std::env::temp_dir().join(format!("pavlov-latest-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(root.join("stall-a")).unwrap();
        std::fs::create_dir_all(root.join("stall-b")).unwrap();
        let link = point(&root, "stall", "stall-a").unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), PathBuf::from("stall-a"));
        point(&root, "stall", "stall-b").unwrap();
        assert_eq!(std::fs::read_link(&link).unwrap(), PathBuf::from("stall-b"));
        std::fs::create_dir_all(root.join("interaction-latest")).unwrap();
        let e = point(&root, "interaction", "stall-a")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a symbolic link"), "{e}");
        assert!(root.join("interaction-latest").is_dir());
        let names: Vec<String> = std::fs::read_dir(&root)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(!names.iter().any(|n| n.contains(".tmp")), "{names:?}");
        let _ = std::fs::remove_dir_all(root);
    }
}
