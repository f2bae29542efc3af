//! Readers of the small real-data fixtures in the repository's `datasets/fixtures` (EuRoC frames as binary PGM,
//! SICK scans as JSON, an Ouster cloud as raw floats; provenance in its README.md), shared by the tests, the
//! benchmarks and any replay tool that wants the same frames.

use std::path::PathBuf;

use bytes::Bytes;

use crate::sensors::{Encoding, Image};

/// Why a fixture could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FixtureError {
    /// The file could not be read.
    #[error("cannot read fixture {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file's content is not what its format says.
    #[error("malformed fixture {path}: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// The fixtures directory of the repository.
pub fn fixtures_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../datasets/fixtures")
}

/// Reads a fixture file.
///
/// # Errors
/// [`FixtureError::Io`].
pub fn read(name: &str) -> Result<Vec<u8>, FixtureError> {
    let path = fixtures_dir().join(name);
    std::fs::read(&path).map_err(|source| FixtureError::Io { path, source })
}

/// Parses a binary PGM (`P5`, maxval 255, `#` comments allowed in the header) into a `mono8` image.
///
/// # Errors
/// A message naming what is wrong.
pub fn parse_pgm(bytes: &[u8]) -> Result<Image, String> {
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if bytes.get(pos) == Some(&b'#') {
            while pos < bytes.len() && bytes[pos] != b'\n' {
                pos += 1;
            }
            continue;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err("pgm header ends early".to_owned());
        }
        fields.push(std::str::from_utf8(&bytes[start..pos]).map_err(|_| "pgm header is not ascii".to_owned())?);
    }
    if fields[0] != "P5" || fields[3] != "255" {
        return Err(format!("pgm magic {} / maxval {} unsupported (need P5 / 255)", fields[0], fields[3]));
    }
    let width: usize = fields[1].parse().map_err(|_| format!("pgm width `{}`", fields[1]))?;
    let height: usize = fields[2].parse().map_err(|_| format!("pgm height `{}`", fields[2]))?;
    let data = bytes.get(pos + 1..).ok_or("pgm has no pixel data")?;
    Image::new(width, height, Encoding::Mono8, Bytes::copy_from_slice(data))
}

/// The three EuRoC cam0 frames (752x480 `mono8`).
///
/// # Errors
/// [`FixtureError`] if a file is missing or malformed.
pub fn euroc_frames() -> Result<Vec<Image>, FixtureError> {
    ["euroc_cam0_000.pgm", "euroc_cam0_047.pgm", "euroc_cam0_094.pgm"]
        .into_iter()
        .map(|name| {
            parse_pgm(&read(name)?)
                .map_err(|reason| FixtureError::Malformed { path: fixtures_dir().join(name), reason })
        })
        .collect()
}

/// The Ouster cloud excerpt as (x, y, z) in metres.
///
/// # Errors
/// [`FixtureError`] if the file is missing or not a whole number of points.
pub fn ouster_points_m() -> Result<Vec<[f32; 3]>, FixtureError> {
    let name = "ouster_os1_128_every8th_ring_xyz_f32le.bin";
    let bytes = read(name)?;
    if bytes.len() % 12 != 0 {
        return Err(FixtureError::Malformed {
            path: fixtures_dir().join(name),
            reason: format!("{} bytes is not a multiple of 12", bytes.len()),
        });
    }
    let float = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    Ok(bytes.chunks_exact(12).map(|p| [float(&p[0..4]), float(&p[4..8]), float(&p[8..12])]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pgm_parser_reads_headers_with_comments_and_refuses_short_data() {
        let image = parse_pgm(b"P5\n# c\n2 1\n255\n\x01\x02").unwrap();
        assert_eq!((image.width, image.height, &image.data[..]), (2, 1, &[1u8, 2][..]));
        assert!(parse_pgm(b"P5\n2 2\n255\n\x01").is_err());
        assert!(parse_pgm(b"P2\n1 1\n255\n\x01").is_err());
    }
}
