//! The calibration board in the stub's scene: where the lab configuration's `[board]` puts it on
//! the target's mount, drawn as geoms (a white plate and one thin black box per run of black
//! cells, from [`hitl_calib::Board::black_rects`], the same cells `hitl calibrate --print-board`
//! prints), so MuJoCo's renderer shows it without texture files. The black boxes' front faces lie
//! in the board plane (z = 0 of the board frame, which points into the board); the white plate
//! sits 0.1 mm behind them. Nothing here collides: the board is a picture, not an obstacle.

use hitl_calib::Board;
use hitl_trajectories::lab::LabConfig;
use std::fmt::Write as _;

/// The board's body name.
pub const BOARD_BODY: &str = "calibration_board";

/// Write the board's body into `x` (inside `<worldbody>`) when `lab` has a `[board]`; a board
/// the lab cannot describe is left out with the reason returned.
pub fn write_board(x: &mut String, lab: &LabConfig) -> Result<(), String> {
    let Some(placement) = &lab.board else { return Ok(()) };
    let board = Board::new(placement).map_err(|e| e.to_string())?;
    let pose = lab.base_in_lab() * lab.target_in_base() * placement.board_in_target();
    let t = pose.translation.vector;
    let q = pose.rotation;
    let _ = writeln!(
        x,
        "    <body name=\"{BOARD_BODY}\" pos=\"{:e} {:e} {:e}\" quat=\"{:e} {:e} {:e} {:e}\">",
        t.x, t.y, t.z, q.w, q.i, q.j, q.k
    );
    let (w, h) = board.extent_m();
    let margin = placement.tag_size_m.max(placement.tag_spacing_m);
    let plate = 0.002;
    let _ = writeln!(
        x,
        "      <geom name=\"board-plate\" type=\"box\" contype=\"0\" conaffinity=\"0\" pos=\"{:e} {:e} {:e}\" size=\"{:e} {:e} {:e}\" rgba=\"0.92 0.92 0.92 1\"/>",
        w / 2.0,
        h / 2.0,
        1e-4 + plate / 2.0,
        w / 2.0 + margin,
        h / 2.0 + margin,
        plate / 2.0
    );
    let ink = 5e-5;
    for (i, [bx, by, bw, bh]) in board.black_rects().into_iter().enumerate() {
        let _ = writeln!(
            x,
            "      <geom name=\"board-ink-{i}\" type=\"box\" contype=\"0\" conaffinity=\"0\" pos=\"{:e} {:e} {:e}\" size=\"{:e} {:e} {:e}\" rgba=\"0.02 0.02 0.02 1\"/>",
            bx + bw / 2.0,
            by + bh / 2.0,
            ink,
            bw / 2.0,
            bh / 2.0,
            ink
        );
    }
    let _ = writeln!(x, "    </body>");
    Ok(())
}
