//! PnP.
