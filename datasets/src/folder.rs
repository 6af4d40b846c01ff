//! A folder of images (and optionally a folder of 16-bit depth PNGs, the n-th depth with the
//! n-th image), played in file-name order at a fixed rate.

use std::path::{Path, PathBuf};

use dynaflow_msg::{CameraInfo, DepthImage, Image};

use crate::Error;
use crate::intrinsics::Intrinsics;
use crate::png::{load_depth, load_rgb, same_size};

/// Glob match on a file name: `*` any run, `?` one character.
fn matches(pattern: &[char], name: &[char]) -> bool {
    match (pattern.split_first(), name.split_first()) {
        (None, None) => true,
        (Some(('*', rest)), _) => matches(rest, name) || name.split_first().is_some_and(|(_, n)| matches(pattern, n)),
        (Some(('?', rest)), Some((_, n))) => matches(rest, n),
        (Some((p, rest)), Some((c, n))) if p == c => matches(rest, n),
        _ => false,
    }
}

/// Files of `dir` whose name matches `pattern`, sorted by name.
pub fn list(dir: &Path, pattern: &str) -> Result<Vec<PathBuf>, Error> {
    let p: Vec<char> = pattern.chars().collect();
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::file(dir, e))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|f| {
            f.is_file() && f.file_name().is_some_and(|n| matches(&p, &n.to_string_lossy().chars().collect::<Vec<_>>()))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// One frame of an [`ImageFolder`].
#[derive(Clone, Debug)]
pub struct FolderFrame {
    /// `index / rate` seconds.
    pub stamp: f64,
    /// The image (RGB8 or Gray8).
    pub image: Image,
    /// The paired depth, when the folder has one.
    pub depth: Option<DepthImage>,
    /// The intrinsics at the image's size.
    pub camera: CameraInfo,
}

/// An opened image folder.
#[derive(Debug)]
pub struct ImageFolder {
    images: Vec<PathBuf>,
    depth: Option<Vec<PathBuf>>,
    intrinsics: Intrinsics,
    rate_hz: f64,
    depth_factor: f64,
    /// The first image's size: every later one must have it (the intrinsics are for it).
    size: Option<(u32, u32)>,
}

impl ImageFolder {
    /// The images of `dir` matching `pattern`, with the depth PNGs of `depth_dir` (as many as
    /// images), at `rate_hz`; depth PNG values are `depth_factor` per metre.
    pub fn open(
        dir: &Path,
        pattern: &str,
        depth_dir: Option<&Path>,
        intrinsics: Intrinsics,
        rate_hz: f64,
        depth_factor: f64,
    ) -> Result<Self, Error> {
        if !dir.is_dir() {
            return Err(Error::file(dir, "not a folder"));
        }
        let images = list(dir, pattern)?;
        if images.is_empty() {
            return Err(Error::file(dir, format!("no file matches `{pattern}`")));
        }
        let depth = match depth_dir {
            None => None,
            Some(ddir) => {
                let d = list(ddir, "*.png")?;
                if d.len() != images.len() {
                    return Err(Error::file(ddir, format!("{} depth PNGs for {} images", d.len(), images.len())));
                }
                Some(d)
            }
        };
        Ok(Self { images, depth, intrinsics, rate_hz, depth_factor, size: None })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.images.len()
    }

    /// Whether the folder has no frame (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// Frame `index`, `None` past the end.
    pub fn frame(&mut self, index: usize) -> Result<Option<FolderFrame>, Error> {
        let Some(path) = self.images.get(index) else { return Ok(None) };
        let image = load_rgb(path)?;
        if let Some((w, h)) = self.size
            && (w, h) != (image.width, image.height)
        {
            let first = self.images.first().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned());
            return Err(Error::file(
                path,
                format!(
                    "{}x{} but the first image ({}) is {w}x{h}",
                    image.width,
                    image.height,
                    first.unwrap_or_default()
                ),
            ));
        }
        self.size = Some((image.width, image.height));
        let depth = match self.depth.as_ref().and_then(|d| d.get(index)) {
            Some(d) => {
                let depth = load_depth(d, self.depth_factor)?;
                same_size(d.display(), (depth.width, depth.height), path.display(), (image.width, image.height))?;
                Some(depth)
            }
            None => None,
        };
        let camera = self.intrinsics.camera_info(image.width, image.height);
        Ok(Some(FolderFrame { stamp: index as f64 / self.rate_hz, image, depth, camera }))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn globs() {
        let m = |p: &str, n: &str| super::matches(&p.chars().collect::<Vec<_>>(), &n.chars().collect::<Vec<_>>());
        assert!(m("*.png", "a.png"));
        assert!(!m("*.png", "a.jpg"));
        assert!(m("img_??.png", "img_01.png"));
        assert!(!m("img_??.png", "img_1.png"));
    }
}
