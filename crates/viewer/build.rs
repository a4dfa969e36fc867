//! Bundles the page in `web/` and embeds it (see `src/assets.rs`).
//!
//! The front end's sources are copied into `OUT_DIR/web`, `npm ci` installs
//! the locked packages there (again only when `package-lock.json` changed),
//! and `node build.mjs` (esbuild) writes the bundle to `OUT_DIR/dist`; the
//! generated `assets.rs` embeds every file of it with `include_bytes!`. The
//! source tree is never written to, and nothing generated is committed.
//!
//! `MOTIONAUG_VIEWER_DIST=DIR` embeds an already built bundle instead (e.g. a
//! container build stage without Node.js). Without Node.js and npm the crate
//! still builds: the page embedded is a notice saying how to get the viewer,
//! and `viewer::BUNDLED` is false (`motionaug view` refuses to start).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it"));
    let web = manifest.join("web");
    for path in ["src", "package.json", "package-lock.json", "build.mjs"] {
        println!("cargo:rerun-if-changed={}", web.join(path).display());
    }
    println!("cargo:rerun-if-env-changed=MOTIONAUG_VIEWER_DIST");

    let (dist, problem) = match std::env::var_os("MOTIONAUG_VIEWER_DIST") {
        Some(dir) => (PathBuf::from(dir), None),
        None => match bundle(&web, &out) {
            Ok(dist) => (dist, None),
            Err(problem) => (PathBuf::new(), Some(problem)),
        },
    };
    let code = match problem {
        None => embed(&dist),
        Some(problem) => {
            for line in problem.lines() {
                println!("cargo:warning=viewer page not built: {line}");
            }
            missing(&out, &problem)
        }
    };
    std::fs::write(out.join("assets.rs"), code).expect("OUT_DIR is writable");
}

/// Copies the sources into `out/web`, installs packages when the lock file
/// changed, runs the bundler; returns the bundle's folder.
fn bundle(web: &Path, out: &Path) -> Result<PathBuf, String> {
    let work = out.join("web");
    copy_tree(&web.join("src"), &work.join("src")).map_err(|e| format!("copying web/src: {e}"))?;
    for file in ["package.json", "package-lock.json", "build.mjs"] {
        std::fs::copy(web.join(file), work.join(file))
            .map_err(|e| format!("copying web/{file}: {e}"))?;
    }
    let lock = std::fs::read(web.join("package-lock.json")).map_err(|e| e.to_string())?;
    let stamp = work.join("node_modules").join(".motionaug-lock");
    if std::fs::read(&stamp).ok().as_deref() != Some(&lock[..]) {
        run(
            Command::new("npm")
                .args(["ci", "--no-audit", "--no-fund", "--prefer-offline"])
                .current_dir(&work),
            "npm ci",
        )?;
        std::fs::write(&stamp, &lock).map_err(|e| e.to_string())?;
    }
    let dist = out.join("dist");
    let _ = std::fs::remove_dir_all(&dist);
    run(
        Command::new("node")
            .arg("build.mjs")
            .env("VIEWER_OUT", &dist)
            .current_dir(&work),
        "node build.mjs",
    )?;
    Ok(dist)
}

fn run(command: &mut Command, what: &str) -> Result<(), String> {
    let output = command.output().map_err(|e| {
        format!(
            "`{what}` could not start ({e}). Install Node.js (18 or newer) and npm, e.g. \
             `apt-get install nodejs npm`, then `cargo clean -p viewer` and build again; everything \
             but `motionaug view` and the service's /viewer works without them"
        )
    })?;
    if output.status.success() {
        return Ok(());
    }
    Err(format!(
        "`{what}` failed ({}):\n{}{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    ))
}

fn copy_tree(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if entry.file_type()?.is_dir() {
            copy_tree(&entry.path(), &target)?;
        } else {
            std::fs::copy(entry.path(), target)?;
        }
    }
    Ok(())
}

fn mime(name: &str) -> &'static str {
    match name.rsplit('.').next().unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "txt" => "text/plain; charset=utf-8",
        "svg" => "image/svg+xml",
        "png" => "image/png",
        _ => "application/octet-stream",
    }
}

/// `ASSETS` with every file of `dist` (flat: esbuild writes one folder).
fn embed(dist: &Path) -> String {
    let mut names: Vec<String> = std::fs::read_dir(dist)
        .unwrap_or_else(|e| panic!("viewer bundle {}: {e}", dist.display()))
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert!(
        names.iter().any(|n| n == "index.html"),
        "viewer bundle {} has no index.html",
        dist.display()
    );
    let mut code =
        String::from("/// Every file of the bundle.\npub static ASSETS: &[Asset] = &[\n");
    for name in names {
        let path = dist.join(&name);
        writeln!(
            code,
            "    Asset {{ path: {name:?}, mime: {:?}, bytes: include_bytes!({:?}) }},",
            mime(&name),
            path.display().to_string()
        )
        .expect("writing to a String");
    }
    code.push_str("];\n/// Whether the real page was built (not the notice).\npub const BUNDLED: bool = true;\n/// Why it was not (empty: it was).\npub const MISSING_BECAUSE: &str = \"\";\n");
    code
}

/// A one-file "bundle" that says why there is no viewer.
fn missing(out: &Path, problem: &str) -> String {
    let escaped = problem
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    let page = format!(
        "<!doctype html><meta charset=utf-8><title>motionaug viewer</title>\
         <h1>The viewer page was not built</h1><pre>{escaped}</pre>"
    );
    let path = out.join("missing.html");
    std::fs::write(&path, page).expect("OUT_DIR is writable");
    format!(
        "/// The notice shown instead of the page.\npub static ASSETS: &[Asset] = &[\n    Asset {{ path: \"index.html\", mime: \"text/html; charset=utf-8\", bytes: include_bytes!({:?}) }},\n];\n/// Whether the real page was built (not the notice).\npub const BUNDLED: bool = false;\n/// Why it was not (empty: it was).\npub const MISSING_BECAUSE: &str = {problem:?};\n",
        path.display().to_string()
    )
}
