//! The embedded interpreter: started once per process, the user's virtual environment on its
//! path, user modules loaded from a file beside the graph or by name, errors as tracebacks.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use pyo3::prelude::*;

/// Why the active virtual environment is not on the path (set once, at start).
static VENV_NOTE: OnceLock<Option<String>> = OnceLock::new();

/// Run `f` with the interpreter, starting it on first use: CPython's own initialisation
/// without its signal handlers (Ctrl-C stays the runtime's), then the site-packages of
/// `VIRTUAL_ENV` (what `source venv/bin/activate` sets) added, so `pip`-installed packages
/// import as they do in that environment's `python`.
pub(crate) fn attach<R>(f: impl for<'py> FnOnce(Python<'py>) -> R) -> R {
    VENV_NOTE.get_or_init(|| {
        Python::initialize();
        Python::attach(add_virtualenv)
    });
    Python::attach(f)
}

/// Adds `$VIRTUAL_ENV/lib/pythonX.Y/site-packages`; a note when it cannot.
fn add_virtualenv(py: Python<'_>) -> Option<String> {
    let venv = PathBuf::from(std::env::var_os("VIRTUAL_ENV")?);
    let added = (|| -> PyResult<Option<String>> {
        let info = py.import("sys")?.getattr("version_info")?;
        let (major, minor): (u32, u32) = (info.getattr("major")?.extract()?, info.getattr("minor")?.extract()?);
        let dir = venv.join("lib").join(format!("python{major}.{minor}")).join("site-packages");
        if !dir.is_dir() {
            return Ok(Some(format!(
                "VIRTUAL_ENV {} has no lib/python{major}.{minor}/site-packages: it was made with another Python than the {major}.{minor} dynaflow embeds, so its packages are not importable",
                venv.display()
            )));
        }
        py.import("site")?.call_method1("addsitedir", (dir.to_string_lossy().into_owned(),))?;
        Ok(None)
    })();
    added.unwrap_or_else(|e| Some(format!("VIRTUAL_ENV {}: {}", venv.display(), describe(py, &e))))
}

/// A note to add to an import error: why the virtual environment's packages may be missing.
pub(crate) fn venv_note() -> Option<&'static str> {
    VENV_NOTE.get().and_then(Option::as_deref)
}

/// A Python exception as Python prints it: the traceback (each frame's file and line), then
/// the exception.
pub(crate) fn describe(py: Python<'_>, e: &PyErr) -> String {
    // The traceback PyO3 fetched with the error, explicitly: before Python 3.12 the
    // exception's own `__traceback__` need not hold the frames it unwound through.
    let lines = py
        .import("traceback")
        .and_then(|m| m.call_method1("format_exception", (e.get_type(py), e.value(py), e.traceback(py))))
        .and_then(|l| l.extract::<Vec<String>>());
    match lines {
        // importlib's own frames (a file module is executed through it) say nothing to the user.
        Ok(lines) => lines
            .concat()
            .lines()
            .filter(|l| !l.trim_start().starts_with("File \"<frozen importlib"))
            .collect::<Vec<_>>()
            .join("\n"),
        Err(_) => e.to_string(),
    }
}

/// Where a node's class lives: `module` as written, resolved.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) enum ModuleRef {
    /// A `.py` file (relative paths resolved against the graph file's folder).
    File(PathBuf),
    /// An importable module name (`package.module`).
    Name(String),
}

impl ModuleRef {
    /// `module` as a graph writes it: a path when it ends in `.py` or names a folder, else a
    /// module name.
    pub(crate) fn parse(module: &str, base_dir: Option<&Path>) -> Self {
        if module.ends_with(".py") || module.contains('/') {
            let p = Path::new(module);
            Self::File(match base_dir {
                Some(dir) if p.is_relative() => dir.join(p),
                _ => p.to_path_buf(),
            })
        } else {
            Self::Name(module.to_owned())
        }
    }
}

impl std::fmt::Display for ModuleRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::File(p) => write!(f, "{}", p.display()),
            Self::Name(n) => f.write_str(n),
        }
    }
}

/// The module: imported by name, or executed from its file once per process (registered as
/// `dynaflow_user.<stem>`, its folder on `sys.path` so it imports its neighbours).
pub(crate) fn import<'py>(py: Python<'py>, module: &ModuleRef) -> Result<Bound<'py, PyModule>, String> {
    let failed = |e: PyErr| {
        let mut text = format!("importing {module} failed:\n{}", describe(py, &e));
        if let Some(note) = venv_note() {
            text.push_str(&format!("\n(note: {note})"));
        }
        text
    };
    match module {
        ModuleRef::Name(name) => py.import(name.as_str()).map_err(failed),
        ModuleRef::File(path) => {
            if !path.is_file() {
                return Err(format!("{}: no such Python file", path.display()));
            }
            let stem = path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            let stem: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
            let name = format!("dynaflow_user.{stem}");
            let path_text = path.to_string_lossy().into_owned();
            let sys = py.import("sys").map_err(failed)?;
            let modules = sys.getattr("modules").map_err(failed)?;
            if let Ok(m) = modules.get_item(&name)
                && m.getattr("__file__").and_then(|f| f.extract::<String>()).is_ok_and(|f| f == path_text)
            {
                return m.cast_into::<PyModule>().map_err(|e| failed(e.into()));
            }
            let load = || -> PyResult<Bound<'py, PyModule>> {
                if let Some(dir) = path.parent() {
                    let dir = dir.to_string_lossy().into_owned();
                    let sys_path = sys.getattr("path")?;
                    if !sys_path.contains(&dir)? {
                        sys_path.call_method1("insert", (0, dir))?;
                    }
                }
                let util = py.import("importlib.util")?;
                let spec = util.call_method1("spec_from_file_location", (&name, &path_text))?;
                let m = util.call_method1("module_from_spec", (&spec,))?;
                modules.set_item(&name, &m)?;
                if let Err(e) = spec.getattr("loader")?.call_method1("exec_module", (&m,)) {
                    let _ = modules.del_item(&name);
                    return Err(e);
                }
                Ok(m.cast_into::<PyModule>()?)
            };
            load().map_err(failed)
        }
    }
}
