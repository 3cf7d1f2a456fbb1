//! campro's per-pixel restoration stage, read from an enhancer file's graph and run here at
//! full resolution.

use super::names::{RESTORE_BINS, RESTORE_TABLE};
#[cfg(doc)]
use super::padded_chw;
use image::RgbImage;

/// campro's per-pixel restoration stage read from its graph's constants
/// (`restore.bins`: each channel's level already scaled to its place in the index;
/// `restore.table`: 2^18 RGB entries), computed as the graph does: the entry of
/// `bins[r] + bins[256 + g] + bins[512 + b]`, times 1/255 in f32 (bit for bit: a test).
#[derive(Debug, Clone)]
pub(super) struct RestoreTable {
    bins: Vec<u32>,
    entries: Vec<u8>,
}

impl RestoreTable {
    /// Entries of the table: 64 bins a channel, cubed.
    const ENTRIES: usize = 1 << 18;

    pub(super) fn from_graph(graph: &tract_onnx::pb::GraphProto) -> Option<Self> {
        let init = |name: &str| graph.initializer.iter().find(|t| t.name == name);
        let table = init(RESTORE_TABLE).filter(|t| t.data_type == 2 && t.raw_data.len() == 3 * Self::ENTRIES)?;
        let bins = init(RESTORE_BINS).filter(|t| t.data_type == 1)?;
        let floats: Vec<f32> = if bins.raw_data.is_empty() {
            bins.float_data.clone()
        } else {
            bins.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        // Three channels' places must sum below the table's size: integers in f32.
        let ok = floats.len() == 768
            && floats.iter().all(|&v| v >= 0.0 && v.fract() == 0.0 && (v as usize) < Self::ENTRIES)
            && (0..3)
                .map(|c| floats[c * 256..(c + 1) * 256].iter().fold(0f32, |m, &v| m.max(v)) as usize)
                .sum::<usize>()
                < Self::ENTRIES;
        ok.then(|| Self { bins: floats.iter().map(|&v| v as u32).collect(), entries: table.raw_data.clone() })
    }

    /// The restored image as (3, `ph`, `pw`) floats, padded as [`padded_chw`] pads.
    #[cfg(test)]
    pub(super) fn restore(&self, img: &RgbImage, pw: usize, ph: usize) -> Vec<f32> {
        self.restore_rows(img, pw, 0..ph)
    }

    /// Rows `rows` of [`Self::restore`]'s image, as (3, rows, `pw`) floats.
    pub(super) fn restore_rows(&self, img: &RgbImage, pw: usize, rows: std::ops::Range<usize>) -> Vec<f32> {
        use rayon::prelude::*;
        let (w, h) = (img.width() as usize, img.height() as usize);
        let (y0, n) = (rows.start, rows.len());
        let plane = pw * n;
        let inv = 1.0f32 / 255.0;
        // Each row's entries, channel after channel (one row of each plane), then the rows
        // put in their planes.
        let mut packed = vec![0f32; 3 * plane];
        packed.par_chunks_mut(3 * pw).enumerate().for_each(|(r, row)| {
            let y = (y0 + r).min(h - 1) as u32;
            for x in 0..pw {
                let p = img.get_pixel(x.min(w - 1) as u32, y).0;
                let i = (self.bins[p[0] as usize] + self.bins[256 + p[1] as usize] + self.bins[512 + p[2] as usize])
                    as usize
                    * 3;
                for c in 0..3 {
                    row[c * pw + x] = self.entries[i + c] as f32 * inv;
                }
            }
        });
        let mut out = vec![0f32; 3 * plane];
        for (r, row) in packed.chunks_exact(3 * pw).enumerate() {
            for c in 0..3 {
                out[c * plane + r * pw..][..pw].copy_from_slice(&row[c * pw..(c + 1) * pw]);
            }
        }
        out
    }
}
