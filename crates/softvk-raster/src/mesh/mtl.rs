//! The MTL files an OBJ names, read for tobj: which file defined each material (its textures
//! are found beside it), which files were missing (a warning, not an error), and the first that
//! failed to parse, checked first for what would make tobj panic.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::MeshError;
use crate::error::one_line;

/// What the MTL loader saw, kept beside tobj (which merges materials and drops their origin).
#[derive(Default)]
pub(super) struct MtlLog {
    /// The MTL file that defined each material, to resolve its texture path and name it.
    pub(super) files: HashMap<String, PathBuf>,
    /// The first MTL that exists but failed to parse.
    pub(super) error: Option<MeshError>,
    /// The MTL files that could not be opened, each once, in file order.
    pub(super) missing: Vec<PathBuf>,
}

impl MtlLog {
    /// Reads one MTL file for tobj, noting what happened.
    pub(super) fn load(&mut self, path: &Path) -> tobj::MTLLoadResult {
        let bytes = match std::fs::read(path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                if !self.missing.iter().any(|m| m == path) {
                    self.missing.push(path.to_path_buf());
                }
                return Err(tobj::LoadError::OpenFileFailed);
            }
            Err(e) => {
                self.fail(path, e.to_string());
                return Err(tobj::LoadError::ReadError);
            }
        };
        if let Err(message) = check_mtl(&bytes) {
            self.fail(path, message);
            return Err(tobj::LoadError::MaterialParseError);
        }
        let result = tobj::load_mtl_buf(&mut bytes.as_slice());
        match &result {
            Ok((materials, _)) => {
                for m in materials {
                    self.files.insert(m.name.clone(), path.to_path_buf());
                }
            }
            Err(e) => self.fail(path, e.to_string()),
        }
        result
    }

    fn fail(&mut self, path: &Path, message: String) {
        self.error.get_or_insert(MeshError::MtlParse {
            path: path.to_path_buf(),
            message,
        });
    }
}

/// What tobj 4 does not check before it panics: a colour (`Ka`, `Kd`, `Ks`, `Ke`) with fewer
/// than three values. The message names the line.
fn check_mtl(bytes: &[u8]) -> Result<(), String> {
    for (i, line) in String::from_utf8_lossy(bytes).lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next()
            && words.count() < 3
        {
            return Err(format!(
                "`{key}` needs three numbers at line {}: `{}`",
                i + 1,
                one_line(line.trim())
            ));
        }
    }
    Ok(())
}
