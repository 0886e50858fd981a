//! The README's recipes run as written (issue #25.5): every `ptm …` line of its `sh` blocks
//! (continuation lines joined, in order, in one folder that holds the repository's `docs/`), with
//! only the first bake's texel count lowered to keep the test short.

use std::path::Path;
use std::process::Command;

/// The `ptm` commands of the README's `sh` blocks, one shell line each, comments removed.
fn readme_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md");
    let mut out = Vec::new();
    let mut in_sh = false;
    let mut line = String::new();
    for raw in readme.lines() {
        if raw.starts_with("```") {
            in_sh = raw == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        // A comment starts at ` # ` outside quotes (the README quotes no `#`).
        let code = raw.split(" # ").next().unwrap_or("").trim_end();
        let code = code.strip_prefix('#').map_or(code, |_| "");
        match code.strip_suffix('\\') {
            Some(head) => line.push_str(head),
            None => {
                line.push_str(code);
                let cmd = line.trim().to_string();
                if cmd.starts_with("ptm ") {
                    out.push(cmd);
                }
                line.clear();
            }
        }
    }
    out
}

#[test]
fn the_readme_recipes_run_as_written() {
    let cmds = readme_commands();
    assert!(
        cmds.iter().any(|c| c.contains("--caster builtin:leaves"))
            && cmds
                .iter()
                .any(|c| c.contains("--images 'docs/examples/capture/")),
        "{cmds:#?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs");
    std::os::unix::fs::symlink(&docs, dir.path().join("docs")).unwrap();
    let bin = Path::new(env!("CARGO_BIN_EXE_ptm")).parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    for cmd in &cmds {
        let cmd = cmd.replace("--res 256", "--res 48");
        let out = Command::new("sh")
            .args(["-c", &cmd])
            .env("PATH", &path)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "`{cmd}` failed:\n{stderr}");
        assert!(
            !stderr.contains("wholly outside the view"),
            "`{cmd}`:\n{stderr}"
        );
    }
    for f in [
        "twill.ptm.exr",
        "preview.png",
        "sheet.png",
        "shadow.png",
        "capture.ptm.exr",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
}
