//! The ICP examples' shared knobs: `POLISH_POINTS`, `PIXEL_ITERS` and `TRACK_PIXEL_ITERS`
//! override the registration's and tracking's pixel-wise refinement (docs/perception.md, "The
//! first registration on every pixel"), so a setting can be tried without a rebuild.

use hitl_perception::icp::IcpConfig;

/// The default ICP configuration with the environment's overrides applied.
pub fn icp_config_from_env() -> IcpConfig {
    let var = |name: &str| std::env::var(name).ok().and_then(|n| n.parse().ok());
    let mut cfg = IcpConfig::default();
    if let Some(n) = var("POLISH_POINTS") {
        cfg.polish_points = n;
    }
    if let Some(n) = var("PIXEL_ITERS") {
        cfg.pixel_iters = n;
    }
    if let Some(n) = var("TRACK_PIXEL_ITERS") {
        cfg.track_pixel_iters = n;
    }
    cfg
}
