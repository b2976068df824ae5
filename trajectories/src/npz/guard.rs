//! A bounds check in front of the NPY library, so hostile headers are refused before anything
//! is allocated or parsed recursively.
//!
//! `npyz` parses the `.npy` header and decodes the data; this module does not replace it. It
//! only looks at what `npyz` would trust blindly: the declared header length (npyz allocates it
//! as stated, up to 4 GiB), the nesting depth of the header's Python literal (parsed
//! recursively), and the declared shape (whose element count npyz multiplies without overflow
//! checks). The header dict itself is read with `py_literal`, the Python-literal library `npyz`
//! uses, and the shape is compared with the bytes the entry actually holds.

use super::error::NpzError;
use py_literal::Value;

/// Largest `.npy` header accepted, bytes. numpy writes ~128; numpy's own reader refuses more than
/// 10 000 by default.
pub const MAX_HEADER_BYTES: usize = 16 * 1024;

/// Deepest bracket nesting accepted in a header (numpy's is 2: the dict and the shape tuple).
const MAX_NESTING: usize = 8;

/// Most dimensions accepted in a shape (the schema's deepest is 3).
const MAX_DIMS: usize = 8;

/// What the guard learnt from an entry's preamble and header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Preamble {
    /// Where the data starts in the entry.
    pub data_offset: usize,
    /// The declared shape.
    pub shape: Vec<u64>,
    /// The declared number of elements (product of `shape`).
    pub elements: u64,
}

const MAGIC: &[u8] = b"\x93NUMPY";

/// Check an entry's `.npy` preamble and header against the bytes it holds.
pub fn inspect(key: &str, bytes: &[u8]) -> Result<Preamble, NpzError> {
    let bad = |detail: String| NpzError::BadNpy { key: key.to_string(), detail };
    if bytes.len() < MAGIC.len() + 4 || &bytes[..MAGIC.len()] != MAGIC {
        return Err(bad("the .npy magic bytes are missing".into()));
    }
    let major = bytes[6];
    let (header_len, prefix) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(bad("the .npy preamble is cut short".into()));
            }
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        v => return Err(bad(format!("unsupported .npy format version {v}"))),
    };
    if header_len > MAX_HEADER_BYTES {
        return Err(NpzError::TooLarge {
            key: key.to_string(),
            detail: format!(
                "the .npy header declares {header_len} bytes (more than {MAX_HEADER_BYTES} are refused)"
            ),
        });
    }
    let data_offset = prefix + header_len;
    if data_offset > bytes.len() {
        return Err(NpzError::Corrupt {
            key: key.to_string(),
            detail: format!(
                "the .npy header declares {header_len} bytes but the entry holds only {}",
                bytes.len() - prefix
            ),
        });
    }
    let text = std::str::from_utf8(&bytes[prefix..data_offset])
        .map_err(|_| bad("the .npy header is not text".into()))?;
    let depth = nesting_depth(text);
    if depth > MAX_NESTING {
        return Err(bad(format!("the .npy header nests {depth} levels deep")));
    }
    let value: Value = text
        .trim_end_matches(['\n', ' ', '\0'])
        .parse()
        .map_err(|e| bad(format!("the .npy header is not a Python literal: {e}")))?;
    let Value::Dict(entries) = value else {
        return Err(bad("the .npy header is not a dict".into()));
    };
    let shape_value = entries
        .iter()
        .find(|(k, _)| matches!(k, Value::String(s) if s == "shape"))
        .map(|(_, v)| v)
        .ok_or_else(|| bad("the .npy header has no 'shape'".into()))?;
    let dims = match shape_value {
        Value::Tuple(d) | Value::List(d) => d,
        _ => return Err(bad("the .npy header's 'shape' is not a tuple".into())),
    };
    if dims.len() > MAX_DIMS {
        return Err(bad(format!("the .npy header declares {} dimensions", dims.len())));
    }
    let mut shape = Vec::with_capacity(dims.len());
    for d in dims {
        let Value::Integer(i) = d else {
            return Err(bad("the .npy header's 'shape' holds a non-integer".into()));
        };
        let v = u64::try_from(i)
            .map_err(|_| bad(format!("the .npy header's 'shape' holds {i}, not a size")))?;
        shape.push(v);
    }
    // Every partial product must fit (npyz multiplies them unchecked, in both orders); zero
    // dimensions are skipped here so a zero cannot hide an overflow elsewhere.
    let nonzero = shape.iter().filter(|d| **d > 0).try_fold(1u64, |acc, d| acc.checked_mul(*d));
    let data_len = (bytes.len() - data_offset) as u64;
    let too_large = |what: String| NpzError::TooLarge {
        key: key.to_string(),
        detail: format!(
            "declares shape {shape:?} ({what}) but the entry holds only {data_len} data bytes"
        ),
    };
    let Some(nonzero) = nonzero else {
        return Err(too_large("more elements than a 64-bit count".into()));
    };
    let elements = if shape.contains(&0) { 0 } else { nonzero };
    // Each element takes at least one byte; the exact byte count is checked once the dtype is
    // known (see `read`), this refuses absurd shapes before npyz sees them.
    if nonzero > data_len.max(1) && elements > 0 {
        return Err(too_large(format!("{elements} elements")));
    }
    Ok(Preamble { data_offset, shape, elements })
}

/// Deepest nesting of brackets in `text`, ignoring quoted strings.
fn nesting_depth(text: &str) -> usize {
    let (mut depth, mut max) = (0usize, 0usize);
    let mut quote: Option<char> = None;
    let mut escaped = false;
    for c in text.chars() {
        if let Some(q) = quote {
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == q {
                quote = None;
            }
            continue;
        }
        match c {
            '\'' | '"' => quote = Some(c),
            '(' | '[' | '{' => {
                depth += 1;
                max = max.max(depth);
            }
            ')' | ']' | '}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    max
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(header: &str, data: usize) -> Vec<u8> {
        let mut v = MAGIC.to_vec();
        v.extend([1, 0]);
        v.extend((header.len() as u16).to_le_bytes());
        v.extend(header.as_bytes());
        v.extend(std::iter::repeat_n(0u8, data));
        v
    }

    #[test]
    fn accepts_what_numpy_writes() {
        let b = npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 7), }\n", 168);
        let p = inspect("qpos", &b).expect("ok");
        assert_eq!(p.shape, vec![3, 7]);
        assert_eq!(p.elements, 21);
        assert_eq!(b.len() - p.data_offset, 168);
        let b = npy("{'descr': '<U5', 'fortran_order': False, 'shape': (), }\n", 20);
        assert_eq!(inspect("meta", &b).expect("0-d").elements, 1);
    }

    #[test]
    fn refuses_huge_and_overflowing_shapes_and_deep_headers() {
        let b = npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 7), }", 16);
        let e = inspect("qpos", &b).expect_err("refused");
        assert!(matches!(e, NpzError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("qpos") && e.to_string().contains("1000000000000"), "{e}");
        let b = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (0, 4294967296, 4294967296), }",
            0,
        );
        assert!(matches!(inspect("t", &b), Err(NpzError::TooLarge { .. })));
        let deep = format!("{}{}", "(".repeat(500), ")".repeat(500));
        assert!(inspect("t", &npy(&deep, 0)).expect_err("refused").to_string().contains("nests"));
        let mut huge = MAGIC.to_vec();
        huge.extend([2, 0]);
        huge.extend(u32::MAX.to_le_bytes());
        assert!(matches!(inspect("t", &huge), Err(NpzError::TooLarge { .. })));
        assert!(inspect("t", b"PK\x03\x04 not npy")
            .expect_err("refused")
            .to_string()
            .contains("magic"));
    }
}
