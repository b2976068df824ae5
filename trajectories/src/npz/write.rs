//! Writing a trajectory as numpy's `savez` / `savez_compressed` do: one `KEY.npy` entry per
//! array, stored or deflated, little-endian, C order, `meta` as a 0-d `<U` string. Entries carry
//! the zip format's default date (1980-01-01), so the same trajectory gives the same bytes.

use super::error::NpzError;
use npyz::{DType, Serialize, TypeStr, WriteOptions, WriterBuilder};
use std::io::{Seek, Write};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

use crate::trajectory::Trajectory;

/// Write `traj` (already validated) into a zip stream; returns the stream.
pub fn write_archive<W: Write + Seek>(
    out: W,
    traj: &Trajectory,
    compressed: bool,
) -> Result<W, NpzError> {
    let method = if compressed { CompressionMethod::Deflated } else { CompressionMethod::Stored };
    let options = SimpleFileOptions::default()
        .compression_method(method)
        .last_modified_time(DateTime::default())
        .unix_permissions(0o644);
    let mut zip = ZipWriter::new(out);
    let n = traj.qpos.len() as u64;
    let mut w = Entries { zip: &mut zip, options };
    w.array("qpos", "<f8", &[n, 7], traj.qpos.iter().flatten())?;
    w.array("t", "<f8", &[n], traj.t.iter())?;
    if let Some(v) = &traj.capture {
        w.array("capture", "|b1", &[n], v.iter())?;
    }
    if let Some(v) = &traj.light {
        w.array("light", "<f4", &[n], v.iter())?;
    }
    if let Some(v) = &traj.u_rad {
        w.array("u_rad", "<f8", &[n], v.iter())?;
    }
    if let Some(v) = &traj.rel_pos_rtn_m {
        w.array("rel_pos_rtn_m", "<f8", &[n, 3], v.iter().flatten())?;
    }
    if let Some(v) = &traj.cam_pose_base {
        w.array("cam_pose_base", "<f8", &[n, 4, 4], v.iter().flatten().flatten())?;
    }
    if let Some(v) = &traj.sun_phase_deg {
        w.array("sun_phase_deg", "<f8", &[n], v.iter())?;
    }
    if let Some(meta) = &traj.meta {
        // numpy spells a 0-d str as `<U{chars}` (at least 1) and pads with NULs.
        let chars = meta.chars().count().max(1);
        w.begin("meta")?;
        let encode =
            |e: std::io::Error| NpzError::Encode { key: "meta".into(), detail: e.to_string() };
        let mut npy = WriteOptions::<str>::new()
            .dtype(dtype(&format!("<U{chars}"), "meta")?)
            .shape(&[])
            .writer(&mut *w.zip)
            .begin_nd()
            .map_err(encode)?;
        npy.push(meta.as_str()).map_err(encode)?;
        npy.finish().map_err(encode)?;
    }
    zip.finish()
        .map_err(|e| NpzError::Encode { key: "(zip directory)".into(), detail: e.to_string() })
}

struct Entries<'a, W: Write + Seek> {
    zip: &'a mut ZipWriter<W>,
    options: SimpleFileOptions,
}

impl<W: Write + Seek> Entries<'_, W> {
    fn begin(&mut self, key: &str) -> Result<(), NpzError> {
        self.zip
            .start_file(format!("{key}.npy"), self.options)
            .map_err(|e| NpzError::Encode { key: key.into(), detail: e.to_string() })
    }

    fn array<'v, T: Serialize + 'v>(
        &mut self,
        key: &str,
        descr: &str,
        shape: &[u64],
        values: impl Iterator<Item = &'v T>,
    ) -> Result<(), NpzError> {
        self.begin(key)?;
        let encode =
            |e: std::io::Error| NpzError::Encode { key: key.into(), detail: e.to_string() };
        // Encode into memory first, then hand the zip layer one buffer: millions of 8-byte writes
        // into the deflate stream cost more than the compression.
        let elements = shape.iter().product::<u64>() as usize;
        let mut buf = Vec::with_capacity(128 + elements * 8);
        let mut npy = WriteOptions::<T>::new()
            .dtype(dtype(descr, key)?)
            .shape(shape)
            .writer(&mut buf)
            .begin_nd()
            .map_err(encode)?;
        for v in values {
            npy.push(v).map_err(encode)?;
        }
        npy.finish().map_err(encode)?;
        self.zip.write_all(&buf).map_err(encode)
    }
}

fn dtype(descr: &str, key: &str) -> Result<DType, NpzError> {
    descr
        .parse::<TypeStr>()
        .map(DType::new_scalar)
        .map_err(|e| NpzError::Encode { key: key.into(), detail: e.to_string() })
}
