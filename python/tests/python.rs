//! The Python tests of `cortex_dsr` (the `*.py` files beside this one, plain unittest), run against the extension
//! this cargo build made: it is put under the target directory as the package maturin installs (`cortex_dsr/`
//! with the extension and an `__init__.py` that re-exports it) and found through `PYTHONPATH`, with the virtual
//! environment `scripts/test-python.sh venv` makes (numpy, cyclonedds) and the workspace's `cortex` binary.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// What maturin writes as the package's `__init__.py` for a module of one extension.
const INIT_PY: &str = "from .cortex_dsr import *\n\n__doc__ = cortex_dsr.__doc__\nif hasattr(cortex_dsr, \"__all__\"):\n    __all__ = cortex_dsr.__all__\n";

fn main() -> ExitCode {
    match run() {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: the Python tests did not run: {error}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<ExitCode, String> {
    // CARGO_TARGET_TMPDIR is `<target directory>/tmp`.
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let target = tmp.parent().ok_or("the target directory is unknown")?;
    let python = target.join("python-venv/bin/python");
    if !python.exists() {
        println!(
            "note: no virtual environment at {}: the Python tests do not run (scripts/test-python.sh makes one)",
            python.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let modules = install(&python, tmp)?;
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let status = Command::new(&python)
        .args(["-m", "unittest", "discover", "-v", "-s"])
        .arg(&tests)
        .arg("-t")
        .arg(&tests)
        .env("PYTHONPATH", modules)
        .env("CARGO_TARGET_DIR", target)
        .status()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    Ok(if status.success() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// Makes `<tmp>/python-module/cortex_dsr/` (the extension this build made, under the name `python` expects, and
/// the `__init__.py`); returns the directory to put on `PYTHONPATH`.
fn install(python: &Path, tmp: &Path) -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot find this test executable: {e}"))?;
    let extension = exe.with_file_name("libcortex_dsr.so");
    if !extension.exists() {
        return Err(format!("no extension at {}", extension.display()));
    }
    let output = Command::new(python)
        .args(["-c", "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))"])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    let suffix = String::from_utf8_lossy(&output.stdout).trim().to_owned();
    if !output.status.success() || suffix.is_empty() {
        return Err("the interpreter gave no extension suffix".to_owned());
    }
    let modules = tmp.join("python-module");
    let package = modules.join("cortex_dsr");
    std::fs::create_dir_all(&package).map_err(|e| format!("cannot create {}: {e}", package.display()))?;
    let module = package.join(format!("cortex_dsr{suffix}"));
    let _ = std::fs::remove_file(&module);
    std::os::unix::fs::symlink(&extension, &module).map_err(|e| format!("cannot link {}: {e}", module.display()))?;
    std::fs::write(package.join("__init__.py"), INIT_PY).map_err(|e| format!("cannot write __init__.py: {e}"))?;
    Ok(modules)
}
