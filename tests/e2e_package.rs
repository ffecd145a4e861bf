//! The Debian package as `scripts/package.sh` writes it, inspected without
//! installing it (no root needed): the control fields, the conffile, the
//! files and their modes, the packaged unit's `ExecStart=/usr/bin/dflat`,
//! and maintainer scripts that parse. A stand-in executable is packaged
//! (`--bin`), so the test does not build the onboard binary; CI's package
//! round trip (`scripts/package-roundtrip.sh`) installs the real one.
//!
//! Skipped, saying so, where `dpkg-deb` is not installed.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("run");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_package_holds_the_daemon_its_unit_and_a_conffile() {
    if Command::new("dpkg-deb").arg("--version").output().is_err() {
        eprintln!("skipped: dpkg-deb not installed (not a Debian system)");
        return;
    }
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("e2e-package-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let stand_in = dir.join("dflat");
    std::fs::write(&stand_in, "#!/bin/sh\necho dflat 0.0.0\n").expect("stand-in");
    run(Command::new("chmod").arg("0755").arg(&stand_in));

    // No lintian here (slow, and CI's round trip runs it).
    let out = run(Command::new(repo().join("scripts/package.sh"))
        .arg("--bin")
        .arg(&stand_in)
        .env("CARGO_TARGET_DIR", &dir)
        .env("DFLAT_PACKAGE_NO_LINTIAN", "1"));
    let deb = out
        .lines()
        .find_map(|l| l.strip_prefix("package: "))
        .and_then(|l| l.split_whitespace().next())
        .map(PathBuf::from)
        .expect("package.sh names its package");
    let name = deb.file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("dflat_") && name.ends_with(".deb") && deb.starts_with(dir.join("debian")),
        "{}",
        deb.display()
    );

    let field = |f: &str| run(Command::new("dpkg-deb").arg("-f").arg(&deb).arg(f));
    assert_eq!(field("Package").trim(), "dflat");
    assert!(
        field("Depends").contains("adduser"),
        "Depends: {}",
        field("Depends")
    );
    let arch = field("Architecture");
    assert!(
        name.contains(&format!("_{}.deb", arch.trim())),
        "{name} vs {arch}"
    );

    let contents = run(Command::new("dpkg-deb").arg("--contents").arg(&deb));
    let mode_of = |path: &str| {
        contents
            .lines()
            .find(|l| l.ends_with(&format!(".{path}")))
            .map(|l| l.split_whitespace().next().unwrap_or("").to_owned())
            .unwrap_or_else(|| panic!("{path} not in the package:\n{contents}"))
    };
    assert_eq!(mode_of("/usr/bin/dflat"), "-rwxr-xr-x");
    assert_eq!(mode_of("/lib/systemd/system/dflat.service"), "-rw-r--r--");
    assert_eq!(mode_of("/etc/dflat/dflat.toml"), "-rw-r--r--");
    assert_eq!(mode_of("/usr/share/doc/dflat/copyright"), "-rw-r--r--");
    assert!(
        contents.lines().all(|l| l.contains(" root/root ")),
        "files not owned by root:\n{contents}"
    );

    let x = dir.join("x");
    run(Command::new("dpkg-deb").arg("-R").arg(&deb).arg(&x));
    let unit = std::fs::read_to_string(x.join("lib/systemd/system/dflat.service")).unwrap();
    assert!(
        unit.lines()
            .any(|l| l == "ExecStart=/usr/bin/dflat daemon --config /etc/dflat/dflat.toml"),
        "{unit}"
    );
    assert!(!unit.contains("/usr/local"), "{unit}");
    // The unit is deploy/dflat.service otherwise: the stop and kill settings
    // the daemon's shutdown relies on are there.
    assert!(unit.lines().any(|l| l == "KillSignal=SIGTERM"));
    let conffiles = std::fs::read_to_string(x.join("DEBIAN/conffiles")).unwrap();
    assert_eq!(conffiles.trim(), "/etc/dflat/dflat.toml");
    assert_eq!(
        std::fs::read(x.join("etc/dflat/dflat.toml")).unwrap(),
        std::fs::read(repo().join("config/default.toml")).unwrap()
    );
    for script in ["postinst", "prerm", "postrm"] {
        let path = x.join("DEBIAN").join(script);
        run(Command::new("sh").arg("-n").arg(&path));
        let text = std::fs::read_to_string(&path).unwrap();
        match script {
            "postinst" => {
                assert!(
                    text.contains("check-config /etc/dflat/dflat.toml"),
                    "{text}"
                );
                assert!(text.contains("dflat dialout"), "{text}");
            }
            "postrm" => assert!(text.contains("purge") && text.contains("deluser"), "{text}"),
            _ => {}
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
