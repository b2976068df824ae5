//! The ICP examples' shared knobs: `POLISH_POINTS`, `PIXEL_ITERS`, `TRACK_PIXEL_ITERS`,
//! `SCREEN_FIT_ITERS`, `FIT_ITERS`, `TRACK_FIT_ITERS`, `TRACK_FIT_MAX_PIXELS`, `COARSE_KEEP`,
//! `POLISH_KEEP` and `MIN_TRACK_AGREEMENT` override the registration's and tracking's
//! refinement against the frame's pixels (docs/perception.md, "The first registration on every
//! pixel" and "Render-and-compare fitting"), so a setting can be tried without a rebuild.

use hitl_perception::icp::IcpConfig;

/// The default ICP configuration with the environment's overrides applied.
pub fn icp_config_from_env() -> IcpConfig {
    fn var<T: std::str::FromStr>(name: &str, field: &mut T) {
        if let Some(v) = std::env::var(name).ok().and_then(|n| n.parse().ok()) {
            *field = v;
        }
    }
    let mut cfg = IcpConfig::default();
    var("POLISH_POINTS", &mut cfg.polish_points);
    var("PIXEL_ITERS", &mut cfg.pixel_iters);
    var("TRACK_PIXEL_ITERS", &mut cfg.track_pixel_iters);
    var("SCREEN_FIT_ITERS", &mut cfg.screen_fit_iters);
    var("FIT_ITERS", &mut cfg.fit_iters);
    var("TRACK_FIT_ITERS", &mut cfg.track_fit_iters);
    var("TRACK_FIT_MAX_PIXELS", &mut cfg.track_fit_max_pixels);
    var("COARSE_KEEP", &mut cfg.coarse_keep);
    var("POLISH_KEEP", &mut cfg.polish_keep);
    var("MIN_TRACK_AGREEMENT", &mut cfg.min_track_agreement);
    cfg
}
