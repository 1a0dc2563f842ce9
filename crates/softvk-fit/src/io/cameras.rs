//! The views of a fit (`--cameras C.csv`): one `distance,elevation,azimuth` row per view,
//! loaded, checked against the silhouettes and written back exactly.

use std::fmt::Write as _;
use std::path::Path;

use super::Silhouettes;
use crate::atomic_file::AtomicFile;
use crate::camera::Camera;
use crate::error::{Error, Result, one_line};

/// One view of a fit: where its camera is, as `render`'s `--distance --elevation --azimuth`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRow {
    /// Distance from the origin, > 0.
    pub distance: f64,
    /// Elevation, degrees.
    pub elevation: f64,
    /// Azimuth, degrees.
    pub azimuth: f64,
}

impl CameraRow {
    /// The look-at camera of this view ([`Camera::from_angles`], perspective).
    pub fn camera(&self) -> Camera {
        Camera::from_angles(self.distance, self.elevation, self.azimuth)
    }
}

/// The header line of a cameras file.
pub const CAMERAS_HEADER: &str = "distance,elevation,azimuth";

/// Loads a cameras file (SPEC §6): the header `distance,elevation,azimuth`, then one row of
/// three numbers per view, angles in degrees, in the order of the silhouettes' file names.
///
/// Spaces around fields, blank lines, CRLF line ends and a UTF-8 byte-order mark are accepted.
/// Errors name the file and line: a missing file, another header, a row without exactly three
/// fields, a field that is not a finite number, a distance that is not > 0, and no rows at all.
pub fn load_cameras(path: &Path) -> Result<Vec<CameraRow>> {
    let text = match std::fs::read(path) {
        Ok(bytes) => String::from_utf8(bytes).map_err(|_| {
            Error::Input(format!("cameras file {}: not UTF-8 text", path.display()))
        })?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::Input(format!(
                "cameras file {}: does not exist",
                path.display()
            )));
        }
        Err(source) => {
            return Err(Error::Io {
                path: path.to_path_buf(),
                source,
            });
        }
    };
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let bad = |line: usize, message: String| Error::Parse {
        what: "cameras file",
        path: path.to_path_buf(),
        line,
        message,
    };

    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((n, header)) = lines.next() else {
        return Err(Error::Input(format!(
            "cameras file {}: is empty; it needs the header `{CAMERAS_HEADER}` and one row per view",
            path.display()
        )));
    };
    let fields: Vec<&str> = header.split(',').map(str::trim).collect();
    if fields != ["distance", "elevation", "azimuth"] {
        return Err(bad(
            n,
            format!(
                "the header is `{}`, not `{CAMERAS_HEADER}`",
                one_line(header.trim())
            ),
        ));
    }

    let mut rows = Vec::new();
    for (n, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != 3 {
            return Err(bad(
                n,
                format!("{} field(s), expected 3 ({CAMERAS_HEADER})", fields.len()),
            ));
        }
        let mut values = [0.0f64; 3];
        for ((value, field), name) in
            values
                .iter_mut()
                .zip(&fields)
                .zip(["distance", "elevation", "azimuth"])
        {
            *value = match field.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                Ok(_) => {
                    return Err(bad(
                        n,
                        format!("{name} `{}` is not a finite number", one_line(field)),
                    ));
                }
                Err(_) => {
                    return Err(bad(
                        n,
                        format!("{name} `{}` is not a number", one_line(field)),
                    ));
                }
            };
        }
        let [distance, elevation, azimuth] = values;
        if distance <= 0.0 {
            return Err(bad(n, format!("distance {distance} must be > 0")));
        }
        rows.push(CameraRow {
            distance,
            elevation,
            azimuth,
        });
    }
    if rows.is_empty() {
        return Err(Error::Input(format!(
            "cameras file {}: has a header but no camera row",
            path.display()
        )));
    }
    Ok(rows)
}

/// Fails with [`Error::Input`] unless there is one camera row per silhouette.
pub fn check_counts(cameras: &[CameraRow], silhouettes: &Silhouettes) -> Result<()> {
    let (c, s) = (cameras.len(), silhouettes.views());
    if c == s {
        return Ok(());
    }
    let plural = |n: usize| if n == 1 { "" } else { "s" };
    Err(Error::Input(format!(
        "{c} camera row{} but {s} silhouette{}: the cameras file needs one row per silhouette, \
         in the order of their file names",
        plural(c),
        plural(s)
    )))
}

/// Writes a cameras file that [`load_cameras`] reads back exactly (shortest round-trip decimals).
/// Every value must be finite and every distance > 0, as the loader requires.
pub fn write_cameras(path: &Path, rows: &[CameraRow]) -> Result<()> {
    let mut text = String::with_capacity(32 * (rows.len() + 1));
    text.push_str(CAMERAS_HEADER);
    text.push('\n');
    for (i, r) in rows.iter().enumerate() {
        let finite = [r.distance, r.elevation, r.azimuth]
            .iter()
            .all(|v| v.is_finite());
        if !finite || r.distance <= 0.0 {
            return Err(Error::Input(format!(
                "cameras for {}: row {i} ({}, {}, {}) needs finite values and a distance > 0",
                path.display(),
                r.distance,
                r.elevation,
                r.azimuth
            )));
        }
        // `{:?}` of an f64 is its shortest round-trip form, and parses back bit for bit.
        let _ = writeln!(text, "{:?},{:?},{:?}", r.distance, r.elevation, r.azimuth);
    }
    AtomicFile::create(path)?.commit(text.as_bytes())
}
