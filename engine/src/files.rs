//! The names of a run's output files, built in one place: `<out>/<stem>.<what>` for the run's
//! own files (summary, recordings) and `<out>/<stem>.<node>.<what>` for an operator's, with
//! `<stem>` the graph name, or `<graph>-<variant>`, so variants and nodes never overwrite each
//! other. The CLI, the operators (through their `Context`) and `bench` all name files here.

use std::path::{Path, PathBuf};

/// Where a run writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunFiles {
    /// The output folder.
    pub dir: PathBuf,
    /// `<graph>` or `<graph>-<variant>`.
    pub stem: String,
}

impl RunFiles {
    /// The files of graph `graph` (and `variant`) in `dir`.
    pub fn new(dir: impl AsRef<Path>, graph: &str, variant: Option<&str>) -> Self {
        Self { dir: dir.as_ref().to_path_buf(), stem: Self::stem_of(graph, variant) }
    }
    /// `<graph>` or `<graph>-<variant>`.
    pub fn stem_of(graph: &str, variant: Option<&str>) -> String {
        match variant {
            Some(v) => format!("{graph}-{v}"),
            None => graph.to_owned(),
        }
    }
    /// `<stem>.summary.json`.
    pub fn summary(&self) -> PathBuf {
        self.run_file("summary.json")
    }
    /// `<stem>.<ext>`: a recording (`rrd`, `mcap`, `messages.jsonl`).
    pub fn run_file(&self, ext: &str) -> PathBuf {
        self.dir.join(format!("{}.{ext}", self.stem))
    }
    /// `<stem>.<node>.<what>`: a file an operator writes (`trajectory.txt`, `ot`, ...).
    pub fn node_file(&self, node: &str, what: &str) -> PathBuf {
        self.dir.join(format!("{}.{node}.{what}", self.stem))
    }
}

/// An output file opened for writing as a *new* file: whatever is at `path` (an old output,
/// or a symlink planted there) is unlinked first, never followed, and the file is created
/// with `O_EXCL`, so a symlink that reappears in between is an error, not a write through
/// it. A directory at `path` is refused; a device or pipe is written as it is. For files
/// written as they grow (recordings).
pub fn create_new(path: &Path) -> std::io::Result<std::fs::File> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory, not a file"));
        }
        Ok(m) if m.is_file() || m.file_type().is_symlink() => std::fs::remove_file(path)?,
        // A device or a pipe (`/dev/null`, `/dev/full`, a FIFO a reader waits on) is written
        // as it is: only its owner (root, for a device) can have put it there.
        Ok(_) => return std::fs::OpenOptions::new().write(true).open(path),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    std::fs::OpenOptions::new().write(true).create_new(true).open(path)
}

/// Write `bytes` to `path` as a new file renamed into place: written beside it under a
/// temporary name (created with `O_EXCL`), then renamed over `path`. A reader never sees half
/// a file, an interrupted write leaves the old file, and a symlink at `path` is replaced, not
/// followed. For files written whole (summaries, maps, vocabularies, masks).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir()) {
        return Err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory, not a file"));
    }
    write_renamed_into_place(
        path,
        |tmp| {
            let mut f = std::fs::OpenOptions::new().write(true).create_new(true).open(tmp)?;
            f.write_all(bytes)?;
            f.sync_data()
        },
        |e| e,
    )
}

/// Have `write` make the file at a temporary name beside `path` (a name nothing else uses),
/// then rename it over `path`; on any failure the temporary file is removed and `path` is left
/// as it was. `rename_error` turns a failed rename into `write`'s error type. For writers that
/// create their file themselves (a rerun recording stream).
pub fn write_renamed_into_place<T, E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
    rename_error: impl FnOnce(std::io::Error) -> E,
) -> Result<T, E> {
    let tmp = temporary_beside(path);
    let written = write(&tmp).and_then(|r| std::fs::rename(&tmp, path).map(|()| r).map_err(rename_error));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// `<dir>/.<name>.<pid>.<n>.tmp`: a temporary name beside `path`, unique in this process.
pub fn temporary_beside(path: &Path) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name = path.file_name().map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// Whether `a` and `b` name the same file: the same device and inode where both exist (hard
/// links, symlinks, `./x` and `x`), else the same absolute path once `.` and `..` and the
/// parent's symlinks are resolved.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    let resolve = |p: &Path| -> Option<PathBuf> {
        if let Ok(c) = std::fs::canonicalize(p) {
            return Some(c);
        }
        let abs = std::path::absolute(p).ok()?;
        let parent = abs.parent().and_then(|d| std::fs::canonicalize(d).ok()).unwrap_or_else(|| abs.clone());
        Some(abs.file_name().map_or(parent.clone(), |n| parent.join(n)))
    };
    matches!((resolve(a), resolve(b)), (Some(x), Some(y)) if x == y)
}

/// Refuse an output that is one of the inputs (`what` names the flag): writing it would
/// destroy the input before, or while, it is read.
pub fn refuse_overwriting_inputs<'a>(
    what: &str,
    out: &Path,
    inputs: impl IntoIterator<Item = &'a Path>,
) -> Result<(), String> {
    for input in inputs {
        if same_file(out, input) {
            return Err(format!(
                "{what} {} is the input {}: writing it would destroy that input; give another name",
                out.display(),
                input.display()
            ));
        }
    }
    Ok(())
}

/// Refuse an output whose name does not end in `.ext` (a `.rrd` written to `x.mcap` would
/// replace an MCAP with a file no MCAP reader opens).
pub fn require_extension(what: &str, out: &Path, ext: &str) -> Result<(), String> {
    let got = out.extension().map(|e| e.to_string_lossy().to_lowercase());
    if got.as_deref() == Some(ext) {
        Ok(())
    } else {
        Err(format!("{what} {}: this command writes a `.{ext}` file; give a name ending in `.{ext}`", out.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("dynaflow-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[cfg(unix)]
    #[test]
    fn outputs_replace_a_planted_symlink_instead_of_writing_through_it() {
        let d = scratch("symlink");
        let (outside, link) = (d.join("outside.txt"), d.join("out").join("summary.json"));
        std::fs::create_dir_all(d.join("out")).unwrap();
        std::fs::write(&outside, "precious").unwrap();
        std::os::unix::fs::symlink(&outside, &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&outside).unwrap(), "precious");
        assert!(!std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        std::fs::remove_file(&link).unwrap();
        std::os::unix::fs::symlink(&outside, &link).unwrap();
        std::io::Write::write_all(&mut create_new(&link).unwrap(), b"grown").unwrap();
        assert_eq!(std::fs::read_to_string(&outside).unwrap(), "precious");
        assert_eq!(std::fs::read_to_string(&link).unwrap(), "grown");
        // No temporary file is left beside it, and a directory is refused.
        assert_eq!(std::fs::read_dir(d.join("out")).unwrap().count(), 1);
        assert!(write_atomic(&d.join("out"), b"x").is_err() && create_new(&d.join("out")).is_err());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn the_same_file_is_recognised_by_any_name() {
        let d = scratch("same");
        let a = d.join("a.mcap");
        std::fs::write(&a, "x").unwrap();
        let dotted = d.join("sub").join("..").join("a.mcap");
        std::fs::create_dir_all(d.join("sub")).unwrap();
        assert!(same_file(&a, &dotted));
        #[cfg(unix)]
        {
            std::fs::hard_link(&a, d.join("hard.mcap")).unwrap();
            assert!(same_file(&a, &d.join("hard.mcap")));
        }
        assert!(!same_file(&a, &d.join("b.mcap")));
        assert!(refuse_overwriting_inputs("--out", &dotted, [a.as_path()]).is_err());
        assert!(require_extension("--out", &d.join("x.MCAP"), "rrd").is_err());
        assert!(require_extension("--out", &d.join("x.rrd"), "rrd").is_ok());
        let _ = std::fs::remove_dir_all(&d);
    }
}
