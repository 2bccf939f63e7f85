//! The dashboard's files: embedded in the binary at compile time (the build script `actors/build.rs`
//! takes `web/*.html`, `web/*.js`, `web/*.css` and uPlot's built files from `web/node_modules`), or, with
//! `serve --web-dir DIR`, read from `DIR` at every request, for working on the page without rebuilding.
//!
//! The routes are the same either way (`routes`): `/` is `index.html`, every script and style sheet of
//! the page is served under its own name, and uPlot under `/vendor/`. Only these names are served, so a
//! directory override cannot expose any other file.

use std::borrow::Cow;
use std::path::PathBuf;

include!(concat!(env!("OUT_DIR"), "/web_assets.rs"));

/// uPlot's script, under `web/`.
pub(crate) const UPLOT_JS: &str = "node_modules/uplot/dist/uPlot.iife.min.js";
/// uPlot's style sheet, under `web/`.
pub(crate) const UPLOT_CSS: &str = "node_modules/uplot/dist/uPlot.min.css";
/// What to run when a `--web-dir` has no uPlot.
pub(crate) const INSTALL_HINT: &str = "run `npm ci --prefix web` in the repository (or leave out --web-dir to use the files built into the binary)";

/// Where the dashboard's files come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WebAssets {
    /// The files compiled into the binary.
    Embedded,
    /// A directory laid out like the repository's `web/` (uPlot in `node_modules/uplot/dist/`), read at
    /// every request (`serve --web-dir`).
    Dir(PathBuf),
}

/// Why a file could not be served.
#[derive(Debug, thiserror::Error)]
pub(crate) enum AssetError {
    /// Not in the `--web-dir` directory.
    #[error("cannot read {path} (from --web-dir): {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not compiled in (a route without a file: a bug of the route table).
    #[error("{0} is not built into this binary")]
    NotEmbedded(&'static str),
}

/// One file the endpoint serves: its URL path, its file under `web/` and its content type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Route {
    /// The URL path, e.g. `/app.js`.
    pub(crate) url: String,
    /// The file under `web/`, e.g. `app.js`.
    pub(crate) file: &'static str,
    /// Its `Content-Type`.
    pub(crate) content_type: &'static str,
}

/// The file embedded as `file` (a path under `web/`).
pub(crate) fn embedded(file: &str) -> Option<&'static [u8]> {
    FILES.iter().find(|(f, _)| *f == file).map(|(_, b)| *b)
}

fn content_type(file: &str) -> &'static str {
    match file.rsplit('.').next() {
        Some("html") => "text/html; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        _ => "text/javascript; charset=utf-8",
    }
}

/// The dashboard's routes: `/` → `index.html`, each of its scripts and style sheets under its name (the
/// fleet page's own files are the fleet server's), uPlot under `/vendor/`.
pub(crate) fn routes() -> Vec<Route> {
    let own = FILES.iter().map(|(f, _)| *f).filter(|f| {
        !f.contains('/') && !f.starts_with("fleet.") && (f.ends_with(".js") || f.ends_with(".css"))
    });
    let mut routes: Vec<Route> = own
        .map(|file| Route {
            url: format!("/{file}"),
            file,
            content_type: content_type(file),
        })
        .collect();
    routes.push(Route {
        url: "/".into(),
        file: "index.html",
        content_type: content_type("index.html"),
    });
    for (url, file) in [
        ("/vendor/uplot.iife.min.js", UPLOT_JS),
        ("/vendor/uplot.min.css", UPLOT_CSS),
    ] {
        routes.push(Route {
            url: url.into(),
            file,
            content_type: content_type(file),
        });
    }
    routes
}

impl WebAssets {
    /// The bytes of `file` (a path under `web/`).
    pub(crate) async fn read(&self, file: &'static str) -> Result<Cow<'static, [u8]>, AssetError> {
        match self {
            WebAssets::Embedded => embedded(file)
                .map(Cow::Borrowed)
                .ok_or(AssetError::NotEmbedded(file)),
            WebAssets::Dir(dir) => {
                let path = dir.join(file);
                tokio::fs::read(&path)
                    .await
                    .map(Cow::Owned)
                    .map_err(|source| AssetError::Read { path, source })
            }
        }
    }

    /// What the start-up banner says about where the page comes from.
    pub fn describe(&self) -> String {
        match self {
            WebAssets::Embedded => format!(
                "built into the binary ({} files, uPlot {UPLOT_VERSION}); --web-dir DIR serves them from a directory instead",
                FILES.len()
            ),
            WebAssets::Dir(dir) => format!("served from {} (--web-dir)", dir.display()),
        }
    }

    /// With `--web-dir`: the files of the page missing from the directory (empty when embedded).
    pub fn missing(&self) -> Vec<PathBuf> {
        match self {
            WebAssets::Embedded => Vec::new(),
            WebAssets::Dir(dir) => routes()
                .into_iter()
                .map(|r| dir.join(r.file))
                .filter(|p| !p.is_file())
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_route_has_its_file_built_in_and_uplot_is_the_real_one() {
        let routes = routes();
        for r in &routes {
            let bytes = embedded(r.file).unwrap_or_else(|| panic!("{} not embedded", r.file));
            assert!(!bytes.is_empty(), "{}", r.file);
        }
        let urls: Vec<&str> = routes.iter().map(|r| r.url.as_str()).collect();
        for url in [
            "/",
            "/app.js",
            "/lib.js",
            "/style.css",
            "/vendor/uplot.iife.min.js",
        ] {
            assert!(urls.contains(&url), "{url} not routed: {urls:?}");
        }
        assert!(!urls.iter().any(|u| u.contains("fleet")), "{urls:?}");
        let uplot = String::from_utf8_lossy(embedded(UPLOT_JS).unwrap_or_default());
        assert!(uplot.contains("uPlot") && uplot.len() > 20_000);
        assert!(
            UPLOT_VERSION
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        );
    }

    #[tokio::test]
    async fn a_directory_serves_what_it_holds_and_names_what_it_lacks() {
        let dir = std::env::temp_dir().join(format!("pavlov-assets-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("index.html"), "<p>dev</p>").unwrap();
        let assets = WebAssets::Dir(dir.clone());
        assert_eq!(&*assets.read("index.html").await.unwrap(), b"<p>dev</p>");
        let e = assets.read(UPLOT_JS).await.unwrap_err();
        assert!(e.to_string().contains("--web-dir"), "{e}");
        let missing = assets.missing();
        assert!(missing.contains(&dir.join(UPLOT_JS)), "{missing:?}");
        assert!(!missing.contains(&dir.join("index.html")));
        assert!(WebAssets::Embedded.missing().is_empty());
        assert!(assets.describe().contains("--web-dir"));
        assert!(
            WebAssets::Embedded
                .describe()
                .contains("built into the binary")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
