//! The browser checks' machinery: the npm packages of `tests/web`, Node.js scripts with a time limit, Chromium,
//! and a small HTTP server for the pages under test.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// `tests/web` with its npm packages installed by `npm ci` (once per run, and only when the lock file is newer than
/// the installed tree, as `scripts/deps.sh` does), or why they cannot be had.
pub fn web() -> Result<&'static Path, String> {
    static CELL: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    CELL.get_or_init(|| {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/web");
        let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
        let (installed, lock) = (
            modified(&dir.join("node_modules/.package-lock.json")),
            modified(&dir.join("package-lock.json")),
        );
        if matches!((installed, lock), (Some(i), Some(l)) if i > l) {
            return Ok(dir);
        }
        let out = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund", "--loglevel=error"])
            .current_dir(&dir)
            .stdin(Stdio::null())
            .output()
            .map_err(|e| format!("npm cannot be run ({e}); install nodejs and npm (scripts/deps.sh)"))?;
        if !out.status.success() {
            return Err(format!(
                "`npm ci` in {} failed, so its packages cannot be installed: {}",
                dir.display(),
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        Ok(dir)
    })
    .as_ref()
    .map(PathBuf::as_path)
    .map_err(Clone::clone)
}

/// Runs `node` with `args` in `dir`, killing it after `limit`; returns stdout, or stderr as the error.
pub fn node(dir: &Path, args: &[&str], limit: Duration) -> Result<String, String> {
    let mut child = Command::new("node")
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("node cannot be run: {e}"))?;
    let (mut stdout, mut stderr) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let out = std::thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).map(|_| s)
    });
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        stderr.read_to_string(&mut s).map(|_| s)
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            return Err(format!("node {args:?} did not finish within {limit:?}"));
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let (out, err) = (out.join().unwrap().unwrap(), err.join().unwrap().unwrap());
    if status.success() {
        if !err.is_empty() {
            eprintln!("node {args:?} said on stderr:\n{err}");
        }
        Ok(out)
    } else {
        Err(format!("node {args:?} failed ({status}):\n{err}"))
    }
}

/// Serves GET requests for files under `routes` (URL prefix -> folder) on a free local port, in the background.
pub fn serve(routes: Vec<(&'static str, PathBuf)>) -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let routes = routes.clone();
            std::thread::spawn(move || respond(stream, &routes));
        }
    });
    port
}

fn respond(mut stream: TcpStream, routes: &[(&str, PathBuf)]) {
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut request = String::new();
    if reader.read_line(&mut request).is_err() {
        return;
    }
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).map_or(true, |n| n == 0) || line == "\r\n" {
            break;
        }
    }
    let target = request.split_whitespace().nth(1).unwrap_or("/");
    let path = target.split('?').next().unwrap_or("/");
    let file = routes.iter().find_map(|(prefix, dir)| {
        let rest = path.strip_prefix(prefix)?;
        (!rest.split('/').any(|part| part == "..")).then(|| dir.join(rest))
    });
    let (status, body, kind) = match file.and_then(|f| std::fs::read(&f).ok().map(|b| (f, b))) {
        Some((f, body)) => {
            let kind = match f.extension().and_then(|e| e.to_str()) {
                Some("html") => "text/html; charset=utf-8",
                Some("js" | "mjs") => "text/javascript",
                Some("glb") => "model/gltf-binary",
                Some("json") => "application/json",
                _ => "application/octet-stream",
            };
            ("200 OK", body, kind)
        }
        None => ("404 Not Found", b"not found".to_vec(), "text/plain"),
    };
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    let _ = stream.write_all(head.as_bytes()).and_then(|()| stream.write_all(&body));
}

/// The Chromium binary (`CHROMIUM`, default `/usr/bin/chromium`, the Debian package), or why there is none.
pub fn chromium() -> Result<PathBuf, String> {
    let path = std::env::var_os("CHROMIUM").map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    if path.exists() {
        Ok(path)
    } else {
        Err(format!(
            "no Chromium at {} (Debian package chromium; scripts/deps.sh installs it; CHROMIUM=PATH selects another)",
            path.display()
        ))
    }
}

/// The WebAssembly build of `radiosity-web` (release, `target/web`, where `radiosity view` looks for it), built
/// once per run after installing the `wasm32-unknown-unknown` target with rustup if it is missing; or why it
/// cannot be had.
pub fn wasm() -> Result<&'static Path, String> {
    static CELL: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    CELL.get_or_init(|| {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let installed =
            Command::new("rustup").args(["target", "list", "--installed"]).output().map_err(|e| {
                format!("rustup cannot be run ({e}); it installs the wasm32-unknown-unknown target")
            })?;
        if !String::from_utf8_lossy(&installed.stdout).lines().any(|l| l.trim() == "wasm32-unknown-unknown") {
            let add = Command::new("rustup")
                .args(["target", "add", "wasm32-unknown-unknown"])
                .output()
                .map_err(|e| format!("rustup cannot be run: {e}"))?;
            if !add.status.success() {
                return Err(format!(
                    "`rustup target add wasm32-unknown-unknown` failed: {}",
                    String::from_utf8_lossy(&add.stderr).trim()
                ));
            }
        }
        let out = Command::new(option_env!("CARGO").unwrap_or("cargo"))
            .args([
                "build",
                "--locked",
                "--release",
                "-p",
                "radiosity-web",
                "--target",
                "wasm32-unknown-unknown",
            ])
            .args(["--target-dir", "target/web"])
            .args(["--config", "profile.release.debug=0", "--config", "profile.release.strip=true"])
            .current_dir(&root)
            .stdin(Stdio::null())
            .output()
            .map_err(|e| format!("cargo cannot be run: {e}"))?;
        // A failing build is a bug of this repository, not a missing package: fail, do not skip.
        assert!(
            out.status.success(),
            "building radiosity-web for wasm32 failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        Ok(root.join("target/web/wasm32-unknown-unknown/release/radiosity_web.wasm"))
    })
    .as_ref()
    .map(PathBuf::as_path)
    .map_err(Clone::clone)
}
