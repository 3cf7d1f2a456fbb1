//! Reading the shared datasets: LFW (folders of `NAME/NAME_000N.jpg`, `pairs.txt`) and the
//! COCO person set (`instances_person.json`, COCO format, category 1 = person).

use crate::ap::GroundTruth;
use crate::error::{EvalError, Result};
use image::RgbImage;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Reads an image as 8-bit RGB through the one hardened reader ([`crate::image_file`]):
/// a regular file, capped, its memory drawn from the process's budget; warnings go to
/// stderr with the path.
pub fn read_rgb8(path: &Path) -> Result<RgbImage> {
    let warn = |m: &str| eprintln!("warning: {}: {m}", campro::file::shown(path));
    let (img, _lease) =
        crate::image_file::read(path, crate::image_file::Budget::global(), &crate::image_file::no_work, &warn)?;
    Ok(img.to_rgb8())
}

/// LFW: identity name -> its image paths (sorted), from `images_deepfunneled` (or the root).
pub struct Lfw {
    pub root: PathBuf,
    pub people: BTreeMap<String, Vec<PathBuf>>,
}

/// One verification pair of `pairs.txt`.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    pub fold: usize,
    pub a: PathBuf,
    pub b: PathBuf,
    pub same: bool,
}

impl Lfw {
    pub fn open(root: &Path) -> Result<Self> {
        let images = if root.join("images_deepfunneled").is_dir() {
            root.join("images_deepfunneled")
        } else {
            root.to_path_buf()
        };
        let mut people = BTreeMap::new();
        for e in std::fs::read_dir(&images).map_err(EvalError::io(&images))? {
            let e = e.map_err(EvalError::io(&images))?;
            if !e.path().is_dir() {
                continue;
            }
            let name = e.file_name().to_string_lossy().into_owned();
            let mut files: Vec<PathBuf> = std::fs::read_dir(e.path())
                .map_err(EvalError::io(e.path()))?
                .filter_map(|f| f.ok().map(|f| f.path()))
                .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("jpg")))
                .collect();
            files.sort();
            if !files.is_empty() {
                people.insert(name, files);
            }
        }
        if people.is_empty() {
            return Err(EvalError::Invalid(format!("{}: no LFW identity folders found", images.display())));
        }
        Ok(Self { root: root.to_path_buf(), people })
    }

    /// The image `NAME/NAME_000N.jpg`, if present in this copy.
    pub fn image(&self, name: &str, n: usize) -> Option<PathBuf> {
        let file = format!("{name}_{n:04}.jpg");
        self.people.get(name)?.iter().find(|p| p.file_name().is_some_and(|f| f == file.as_str())).cloned()
    }

    /// Parses `pairs.txt` (10 folds of same then different pairs); pairs naming an absent
    /// image are skipped and counted (the second value).
    pub fn pairs(&self) -> Result<(Vec<Pair>, usize)> {
        let path = self.root.join("pairs.txt");
        let text = campro::file::read_text_capped(&path, 16 << 20, "LFW pairs.txt")?;
        parse_pairs(&text, &path, |name, n| self.image(name, n))
    }
}

/// Parses the `pairs.txt` format; `find` resolves (name, number) to a path or None.
pub fn parse_pairs(
    text: &str,
    path: &Path,
    find: impl Fn(&str, usize) -> Option<PathBuf>,
) -> Result<(Vec<Pair>, usize)> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let bad = |line: usize, message: String| EvalError::Data { path: path.into(), line: line + 1, message };
    let (hl, head) = lines.next().ok_or_else(|| bad(0, "empty file".into()))?;
    let nums: Vec<usize> = head
        .split_whitespace()
        .map(|t| t.parse())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad(hl, "header must be 'FOLDS PAIRS'".into()))?;
    let [folds, per] = nums[..] else { return Err(bad(hl, "header must be 'FOLDS PAIRS'".into())) };
    let (mut pairs, mut skipped) = (Vec::new(), 0);
    for fold in 0..folds {
        for same in [true, false] {
            for _ in 0..per {
                let (ln, l) =
                    lines.next().ok_or_else(|| bad(usize::MAX - 1, format!("file ends inside fold {}", fold + 1)))?;
                let t: Vec<&str> = l.split_whitespace().collect();
                let num = |s: &str| s.parse::<usize>().map_err(|_| bad(ln, format!("{s:?} is not an image number")));
                let (a, b) = match (same, t.as_slice()) {
                    (true, [n, i, j]) => (find(n, num(i)?), find(n, num(j)?)),
                    (false, [n, i, m, j]) => (find(n, num(i)?), find(m, num(j)?)),
                    _ => {
                        return Err(bad(
                            ln,
                            format!(
                                "expected a {} pair line",
                                if same { "same (name n1 n2)" } else { "different (name1 n1 name2 n2)" }
                            ),
                        ))
                    }
                };
                match (a, b) {
                    (Some(a), Some(b)) => pairs.push(Pair { fold, a, b, same }),
                    _ => skipped += 1,
                }
            }
        }
    }
    Ok((pairs, skipped))
}

/// Every this many COCO ids, one is held out of detector fine-tuning: an image is held out
/// iff its id is a multiple of it (about 20% of the set). `campro train` and
/// `campro finetune-detector` never train on these; `eval utility --held-out` (implied by
/// `--own-detector`) scores only them.
pub const HOLDOUT_EVERY: u64 = 5;

/// Whether the COCO image `id` is held out of detector fine-tuning (see [`HOLDOUT_EVERY`]).
pub fn detector_held_out(id: u64) -> bool {
    id.is_multiple_of(HOLDOUT_EVERY)
}

/// One COCO image with its person boxes.
pub struct CocoImage {
    pub id: u64,
    pub path: PathBuf,
    pub gts: Vec<GroundTruth>,
}

#[derive(serde::Deserialize)]
struct CocoFile {
    images: Vec<CocoImg>,
    annotations: Vec<CocoAnn>,
}
#[derive(serde::Deserialize)]
struct CocoImg {
    id: u64,
    file_name: String,
}
#[derive(serde::Deserialize)]
struct CocoAnn {
    image_id: u64,
    category_id: u64,
    bbox: [f32; 4],
    #[serde(default)]
    iscrowd: u8,
}

/// Reads `instances_person.json` under `root` (images in `root/images`), sorted by id.
pub fn coco_person(root: &Path) -> Result<Vec<CocoImage>> {
    let path = root.join("instances_person.json");
    let text = campro::file::read_text_capped(&path, 64 << 20, "COCO annotations")?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let file: CocoFile = serde_path_to_error::deserialize(de).map_err(|e| EvalError::Data {
        path: path.clone(),
        line: e.inner().line(),
        message: format!("{}: {}", e.path(), e.inner()),
    })?;
    let mut by_id: BTreeMap<u64, CocoImage> = file
        .images
        .into_iter()
        .map(|i| (i.id, CocoImage { id: i.id, path: root.join("images").join(i.file_name), gts: Vec::new() }))
        .collect();
    for a in file.annotations {
        if a.category_id != 1 {
            continue;
        }
        if a.bbox.iter().any(|v| !v.is_finite()) || a.bbox[2] < 0.0 || a.bbox[3] < 0.0 {
            return Err(EvalError::Invalid(format!(
                "{}: annotation of image {} has a bad bbox {:?}",
                path.display(),
                a.image_id,
                a.bbox
            )));
        }
        let img = by_id.get_mut(&a.image_id).ok_or_else(|| {
            EvalError::Invalid(format!("{}: annotation names unknown image {}", path.display(), a.image_id))
        })?;
        img.gts.push(GroundTruth { bbox: a.bbox, crowd: a.iscrowd != 0 });
    }
    Ok(by_id.into_values().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_parse_and_skip_absent_people() {
        let text = "2\t1\nAl\t1\t2\nAl\t1\tBo\t1\nBo\t1\t2\nCy\t1\tAl\t2\n";
        let find = |n: &str, i: usize| (n != "Cy").then(|| PathBuf::from(format!("{n}_{i:04}.jpg")));
        let (pairs, skipped) = parse_pairs(text, Path::new("pairs.txt"), find).unwrap();
        assert_eq!(skipped, 1);
        assert_eq!(pairs.len(), 3);
        assert_eq!(pairs[1], Pair { fold: 0, a: "Al_0001.jpg".into(), b: "Bo_0001.jpg".into(), same: false });
        assert_eq!(pairs[2].fold, 1);
        let err = parse_pairs("1\t2\nAl\t1\t2\n", Path::new("p.txt"), find).unwrap_err().to_string();
        assert!(err.contains("fold 1"), "{err}");
        let err = parse_pairs("1\t1\nAl\tx\t2\nAl\t1\tBo\t1\n", Path::new("p.txt"), find).unwrap_err().to_string();
        assert!(err.contains("p.txt:2") && err.contains("image number"), "{err}");
    }
}
