//! The interactive viewer, under a virtual X server: `btfmrf view --frames N --screenshot`
//! must open a window, render and save non-trivial window contents. Skips with a message when
//! `Xvfb` is not installed (`scripts/setup` installs it), and fails when `CI` is set.

mod common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// An Xvfb server on a free display, killed when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_xvfb() -> Option<Xvfb> {
    let found = Command::new("sh")
        .args(["-c", "command -v Xvfb"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        common::skip_unless_ci("Xvfb is not installed");
        return None;
    }
    let base = 100 + std::process::id() % 400;
    for n in (base..base + 50).filter(|n| !Path::new(&format!("/tmp/.X{n}-lock")).exists()) {
        let child = Command::new("Xvfb")
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "640x480x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb starts");
        let mut server = Xvfb {
            child,
            display: format!(":{n}"),
        };
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(20) {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                return Some(server);
            }
            if let Ok(Some(_)) = server.child.try_wait() {
                break; // this display was taken after all: try the next one
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    panic!("no Xvfb display could be started");
}

#[test]
fn the_viewer_renders_frames_and_saves_a_screenshot_under_xvfb() {
    let Some(x) = start_xvfb() else { return };
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("shot.png");
    let runtime = dir.path().join("runtime");
    std::fs::create_dir(&runtime).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700)).unwrap();
    }
    let model = common::repo().join("tests/golden/sponge64.btfm");
    let out = Command::new(env!("CARGO_BIN_EXE_btfmrf"))
        .args([
            "view",
            model.to_str().unwrap(),
            "--size",
            "200x150",
            "--tile",
            "64",
            "--frames",
            "3",
            "--screenshot",
            shot.to_str().unwrap(),
        ])
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .env("XDG_RUNTIME_DIR", &runtime)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "btfmrf view failed:\n{stderr}");
    let image = image::open(&shot).expect("a screenshot PNG").to_rgb8();
    assert_eq!(image.dimensions(), (200, 150));
    // Non-trivial: a black background around a lit, textured object.
    let pixels: Vec<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    let black = pixels.iter().filter(|p| p.iter().all(|&c| c < 3)).count();
    let lit = pixels.iter().filter(|p| p.iter().any(|&c| c > 40)).count();
    let distinct: std::collections::HashSet<[u8; 3]> = pixels.iter().copied().collect();
    assert!(black > pixels.len() / 10, "{black} black pixels");
    assert!(lit > pixels.len() / 10, "{lit} lit pixels");
    assert!(distinct.len() > 100, "{} distinct colours", distinct.len());
}

/// `btfmrf view ARGS` with no display at all (X11 and Wayland variables removed).
fn view_without_display(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_btfmrf"))
        .arg("view")
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap()
}

#[test]
fn the_viewer_without_a_display_fails_cleanly() {
    let model = common::repo().join("tests/golden/sponge64.btfm");
    let out = view_without_display(&[model.to_str().unwrap(), "--frames", "1"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("error: window"), "{stderr}");
}

#[test]
fn the_viewer_over_the_memory_budget_is_refused_before_any_window() {
    // The ready stones finish every frontal light's pair (81) beside their 20 clusters.
    let model = common::repo().join("models/stones.btfm");
    let out = view_without_display(&[
        model.to_str().unwrap(),
        "--tile",
        "2048",
        "--memory-limit",
        "1G",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("view with a 2048^2 tile"), "{stderr}");
    assert!(stderr.contains("--tile 256 fits"), "{stderr}");
    assert!(!stderr.contains("error: window"), "{stderr}");
}
