//! How a recording's chunks are compressed: the choice, its name on the command line
//! (`none`, `lz4`, `zstd`, `zstd:LEVEL`), and the mcap writer options it stands for.

use std::fmt;
use std::str::FromStr;

/// Compression of the chunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkCompression {
    None,
    /// zstd at the given level (1 is fast, 19 the smallest).
    Zstd(u32),
    Lz4,
}

impl ChunkCompression {
    /// The mcap writer's compression and level.
    pub(crate) fn mcap(self) -> (Option<mcap::Compression>, u32) {
        match self {
            ChunkCompression::None => (None, 0),
            ChunkCompression::Zstd(level) => (Some(mcap::Compression::Zstd), level),
            ChunkCompression::Lz4 => (Some(mcap::Compression::Lz4), 0),
        }
    }
}

/// Why a compression name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown compression '{0}' (expected none, lz4, zstd or zstd:LEVEL with LEVEL 1-19)")]
pub struct CompressionParseError(pub String);

impl FromStr for ChunkCompression {
    type Err = CompressionParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let refuse = || CompressionParseError(s.to_string());
        match s.trim().to_ascii_lowercase().as_str() {
            "none" => Ok(Self::None),
            "lz4" => Ok(Self::Lz4),
            "zstd" => Ok(Self::Zstd(1)),
            other => match other.strip_prefix("zstd:").map(str::parse::<u32>) {
                Some(Ok(level)) if (1..=19).contains(&level) => Ok(Self::Zstd(level)),
                _ => Err(refuse()),
            },
        }
    }
}

impl fmt::Display for ChunkCompression {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::None => f.write_str("none"),
            Self::Lz4 => f.write_str("lz4"),
            Self::Zstd(level) => write!(f, "zstd:{level}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_ones_are_named_in_the_error() {
        for (name, c) in [
            ("none", ChunkCompression::None),
            ("lz4", ChunkCompression::Lz4),
            ("zstd:1", ChunkCompression::Zstd(1)),
            ("zstd:19", ChunkCompression::Zstd(19)),
        ] {
            assert_eq!(name.parse::<ChunkCompression>(), Ok(c));
            assert_eq!(c.to_string(), name);
        }
        assert_eq!("ZSTD".parse::<ChunkCompression>(), Ok(ChunkCompression::Zstd(1)));
        for bad in ["gzip", "zstd:0", "zstd:20", "zstd:", "zstd:x", "lz4:1", ""] {
            let e = bad.parse::<ChunkCompression>().expect_err(bad);
            assert!(e.to_string().contains(&format!("'{bad}'")), "{e}");
        }
    }
}
