//! The tag36h11 family table as the AprilTag C library holds it: its codes and where each code
//! bit sits in the tag. Read once through the library's FFI so that the board we draw is exactly
//! what its detector decodes; nothing of the table is written here.
#![allow(unsafe_code)]

use apriltag::families::{ApriltagFamily, Tag36h11};

/// A tag family's layout and codes (the C library's `apriltag_family_t`, copied).
#[derive(Debug, Clone)]
pub struct FamilyTable {
    /// One code per tag id.
    pub codes: Vec<u64>,
    /// Bits per code.
    pub nbits: usize,
    /// Cell (x, y) of code bit `nbits - 1 - i` inside the black square, per `i`.
    pub bit_x: Vec<u32>,
    pub bit_y: Vec<u32>,
    /// Cells across the black square.
    pub width_at_border: usize,
}

/// The library's tag36h11 table.
pub fn tag36h11() -> FamilyTable {
    let raw = Tag36h11::default().into_raw();
    // SAFETY: `tag36h11_create` returned a family whose `codes` holds `ncodes` values and whose
    // `bit_x`/`bit_y` hold `nbits` values each; they live until `tag36h11_destroy` below, and
    // we copy them out before it. `into_raw` handed ownership to us, so nothing else frees it.
    let table = unsafe {
        let f = &*raw;
        FamilyTable {
            codes: std::slice::from_raw_parts(f.codes, f.ncodes as usize).to_vec(),
            nbits: f.nbits as usize,
            bit_x: std::slice::from_raw_parts(f.bit_x, f.nbits as usize).to_vec(),
            bit_y: std::slice::from_raw_parts(f.bit_y, f.nbits as usize).to_vec(),
            width_at_border: f.width_at_border as usize,
        }
    };
    // SAFETY: `raw` came from `tag36h11_create` (through `Tag36h11::default`) and is freed once.
    unsafe { apriltag_sys::tag36h11_destroy(raw) };
    table
}
