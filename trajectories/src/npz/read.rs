//! Reading an NPZ archive into raw arrays: the zip layer (`zip` crate), the bounds guard, then
//! the `.npy` layer (`npyz`). Knows dtypes and byte counts, not the schema's meaning.

use super::error::NpzError;
use super::guard;
use super::schema;
use npyz::{DType, NpyFile, Order, TypeChar};
use std::collections::BTreeMap;
use std::io::{Read, Seek};

/// Largest single entry accepted, bytes (uncompressed). 256 MiB holds `cam_pose_base` for two
/// million waypoints; a lab trajectory is a few MB.
pub const MAX_ENTRY_BYTES: u64 = 256 << 20;

/// Most warnings kept about ignored entries (an archive of a million junk entries must not make
/// an unbounded list).
const MAX_WARNINGS: usize = 32;

/// The decoded values of one array.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    F64(Vec<f64>),
    F32(Vec<f32>),
    Bool(Vec<bool>),
    Str(String),
}

/// One array as stored: shape, memory order, values in stored order.
#[derive(Debug, Clone, PartialEq)]
pub struct RawArray {
    pub shape: Vec<u64>,
    pub fortran: bool,
    pub data: Data,
    /// The dtype as numpy spells it, for messages (`<f8`, `|b1`, ...).
    pub dtype: String,
}

/// Read every schema key of the archive; unknown entries are named in `warnings` and never
/// decoded.
pub fn read_archive<R: Read + Seek>(
    reader: R,
    warnings: &mut Vec<String>,
) -> Result<BTreeMap<String, RawArray>, NpzError> {
    let mut zip =
        zip::ZipArchive::new(reader).map_err(|e| NpzError::NotZip { detail: e.to_string() })?;
    let mut arrays = BTreeMap::new();
    let mut ignored = 0usize;
    for i in 0..zip.len() {
        let mut entry = zip
            .by_index(i)
            .map_err(|e| NpzError::Corrupt { key: format!("#{i}"), detail: e.to_string() })?;
        if entry.is_dir() {
            continue;
        }
        let name = entry.name().map(|n| n.into_owned()).unwrap_or_else(|_| format!("#{i}"));
        let known = name.strip_suffix(".npy").filter(|k| schema::is_known(k)).map(str::to_string);
        let Some(key) = known else {
            ignored += 1;
            if ignored <= MAX_WARNINGS {
                warnings.push(format!("unknown key '{name}' ignored"));
            }
            continue;
        };
        if arrays.contains_key(&key) {
            return Err(NpzError::BadNpy { key, detail: "the key appears twice".into() });
        }
        let size = entry.size();
        if size > MAX_ENTRY_BYTES {
            return Err(NpzError::TooLarge {
                key,
                detail: format!(
                    "the entry is {size} bytes (more than {MAX_ENTRY_BYTES} are refused)"
                ),
            });
        }
        // Reserve what the directory declares, up to 16 MiB; beyond that the buffer grows only as
        // real bytes arrive, so a tiny file declaring huge entries allocates little.
        let mut bytes = Vec::with_capacity(size.min(16 << 20) as usize);
        (&mut entry)
            .take(size)
            .read_to_end(&mut bytes)
            .map_err(|e| NpzError::Corrupt { key: key.clone(), detail: e.to_string() })?;
        if (bytes.len() as u64) < size {
            return Err(NpzError::Corrupt {
                key,
                detail: format!("the entry ends after {} of its {size} bytes", bytes.len()),
            });
        }
        let array = decode(&key, &bytes)?;
        arrays.insert(key, array);
    }
    if ignored > MAX_WARNINGS {
        warnings.push(format!("... and {} more unknown keys ignored", ignored - MAX_WARNINGS));
    }
    Ok(arrays)
}

/// Decode one `.npy` entry held in memory.
pub fn decode(key: &str, bytes: &[u8]) -> Result<RawArray, NpzError> {
    let pre = guard::inspect(key, bytes)?;
    let npy = NpyFile::new(bytes)
        .map_err(|e| NpzError::BadNpy { key: key.to_string(), detail: e.to_string() })?;
    let header = npy.header();
    if header.uses_pickled_array() {
        return Err(NpzError::Pickled { key: key.to_string() });
    }
    let dtype = header.dtype();
    let expected = schema::expected_dtype(key);
    let refuse = |found: String| NpzError::DType { key: key.to_string(), found, expected };
    let ts = match &dtype {
        DType::Plain(ts) => ts.clone(),
        other => return Err(refuse(format!("{} (structured)", other.descr()))),
    };
    let item = ts.num_bytes().ok_or_else(|| refuse(ts.to_string()))? as u64;
    let data_len = (bytes.len() - pre.data_offset) as u64;
    let needed = pre.elements.checked_mul(item);
    if needed != Some(data_len) {
        return Err(NpzError::TooLarge {
            key: key.to_string(),
            detail: format!(
                "declares shape {:?} of {ts} ({} bytes) but the entry holds {data_len} data bytes",
                pre.shape,
                needed.map_or("more than 2^64".to_string(), |n| n.to_string()),
            ),
        });
    }
    let fortran = header.order() == Order::Fortran;
    let shape = header.shape().to_vec();
    let dtype_name = ts.to_string();
    let bad = |e: std::io::Error| NpzError::BadNpy { key: key.to_string(), detail: e.to_string() };
    let data = match (ts.type_char(), ts.size_field()) {
        (TypeChar::Float, 8) => Data::F64(npy.into_vec::<f64>().map_err(bad)?),
        (TypeChar::Float, 4) => Data::F32(npy.into_vec::<f32>().map_err(bad)?),
        (TypeChar::Bool, _) => Data::Bool(npy.into_vec::<bool>().map_err(bad)?),
        (TypeChar::UnicodeStr, _) => {
            let mut v = npy.into_vec::<String>().map_err(bad)?;
            if v.len() != 1 {
                return Err(NpzError::Shape {
                    key: key.to_string(),
                    found: shape,
                    expected: "() (a 0-d string)".into(),
                });
            }
            Data::Str(v.pop().unwrap_or_default())
        }
        (TypeChar::Int | TypeChar::Uint, _) => {
            return Err(refuse(format!("{ts} (integer)")));
        }
        (TypeChar::Complex, _) => return Err(refuse(format!("{ts} (complex)"))),
        (TypeChar::Object, _) => return Err(NpzError::Pickled { key: key.to_string() }),
        _ => return Err(refuse(ts.to_string())),
    };
    Ok(RawArray { shape, fortran, data, dtype: dtype_name })
}
