//! NumPy `.npy` arrays and `.npz` archives, as the NMR/SoftRas dataset stores its images and
//! voxels: typed data (u8, bool, i32, i64, f32, f64) with a shape, C order only.
//!
//! The `.npy` header and element coding are [`npyz`]'s; the zip archive around them is the `zip`
//! crate's, used directly (deflate only) rather than through npyz's `npz` feature, which turns on
//! zip's default features and with them C builds of zstd and bzip2 that an `.npz` never needs.
//! Writes are deterministic (fixed entry time and permissions, so the same arrays give the same
//! bytes) and atomic ([`AtomicFile`]).
//!
//! Every way an input can be malformed (not a zip, no array, bad magic or header, a dtype softvk
//! does not read, Fortran order, data shorter or longer than shape × item size, a corrupted
//! deflate stream) is one [`Error::Input`] naming the file and, in an archive, the array.

use std::io::{Cursor, Read as _, Write as _};
use std::path::Path;

use npyz::{DType, Order, TypeChar, WriterBuilder as _};

use crate::atomic_file::AtomicFile;
use crate::error::{Error, Result};

/// An array's elements, flat in C order, by element type.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// `uint8` (`|u1`).
    U8(Vec<u8>),
    /// `bool` (`|b1`).
    Bool(Vec<bool>),
    /// `int32` (`<i4` or `>i4`).
    I32(Vec<i32>),
    /// `int64` (`<i8` or `>i8`): indices, as PyTorch and NumPy write them.
    I64(Vec<i64>),
    /// `float32` (`<f4` or `>f4`).
    F32(Vec<f32>),
    /// `float64` (`<f8` or `>f8`).
    F64(Vec<f64>),
}

impl NpyData {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            NpyData::U8(v) => v.len(),
            NpyData::Bool(v) => v.len(),
            NpyData::I32(v) => v.len(),
            NpyData::I64(v) => v.len(),
            NpyData::F32(v) => v.len(),
            NpyData::F64(v) => v.len(),
        }
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// NumPy's name of the element type: `uint8`, `bool`, `int32`, `float32`, `float64`.
    pub fn dtype_name(&self) -> &'static str {
        match self {
            NpyData::U8(_) => "uint8",
            NpyData::Bool(_) => "bool",
            NpyData::I32(_) => "int32",
            NpyData::I64(_) => "int64",
            NpyData::F32(_) => "float32",
            NpyData::F64(_) => "float64",
        }
    }
}

/// A NumPy array: shape and C-order data.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The shape; empty for a 0-d array (one element).
    pub shape: Vec<usize>,
    /// The elements, C order (last axis fastest).
    pub data: NpyData,
}

impl NpyArray {
    /// An array, checked: the product of `shape` must be `data.len()`.
    pub fn new(shape: Vec<usize>, data: NpyData) -> Result<NpyArray> {
        let n = element_count(&shape)
            .ok_or_else(|| Error::Input(format!("array shape {shape:?} overflows")))?;
        if n != data.len() {
            return Err(Error::Input(format!(
                "array shape {shape:?} holds {n} elements, but {} were given",
                data.len()
            )));
        }
        Ok(NpyArray { shape, data })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Whether there are no elements (some axis is 0).
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The elements as truth values: nonzero for the integer types, ≥ 0.5 for the float types
    /// (NaN is false): how a voxel grid of any of these types reads as occupancy.
    pub fn to_bools(&self) -> Vec<bool> {
        match &self.data {
            NpyData::U8(v) => v.iter().map(|&x| x != 0).collect(),
            NpyData::Bool(v) => v.clone(),
            NpyData::I32(v) => v.iter().map(|&x| x != 0).collect(),
            NpyData::I64(v) => v.iter().map(|&x| x != 0).collect(),
            NpyData::F32(v) => v.iter().map(|&x| x >= 0.5).collect(),
            NpyData::F64(v) => v.iter().map(|&x| x >= 0.5).collect(),
        }
    }

    /// The `.npy` file of this array (format 1.0, C order, little endian).
    pub fn to_npy_bytes(&self) -> Vec<u8> {
        let shape: Vec<u64> = self.shape.iter().map(|&s| s as u64).collect();
        let mut out = Vec::with_capacity(128 + self.len() * 8);
        let result = match &self.data {
            NpyData::U8(v) => write_typed(&mut out, &shape, "|u1", v),
            NpyData::Bool(v) => write_typed(&mut out, &shape, "|b1", v),
            NpyData::I32(v) => write_typed(&mut out, &shape, "<i4", v),
            NpyData::I64(v) => write_typed(&mut out, &shape, "<i8", v),
            NpyData::F32(v) => write_typed(&mut out, &shape, "<f4", v),
            NpyData::F64(v) => write_typed(&mut out, &shape, "<f8", v),
        };
        // Writing into a Vec cannot fail, and the element count matches the shape by
        // construction (`NpyArray::new`); a hand-built mismatched array is a caller bug.
        result.expect("an .npy into memory: the data must match the shape");
        out
    }

    /// Parses an `.npy` file's bytes. `what` names the input in errors (a file, or an array of
    /// an archive).
    pub fn from_npy_bytes(bytes: &[u8], what: &str) -> Result<NpyArray> {
        let bad = |why: String| Error::Input(format!("{what}: {why}"));
        if !bytes.starts_with(b"\x93NUMPY") {
            return Err(bad("not a NumPy .npy array (bad magic)".into()));
        }
        let mut rest: &[u8] = bytes;
        let header = npyz::NpyHeader::from_reader(&mut rest)
            .map_err(|e| bad(format!("malformed .npy header: {e}")))?;
        if header.order() == Order::Fortran {
            return Err(bad(
                "Fortran-order array; only C order is read (np.ascontiguousarray before saving)"
                    .into(),
            ));
        }
        let dtype = header.dtype();
        let (kind, item) = match &dtype {
            DType::Plain(ts) => (ts.type_char(), ts.size_field() as usize),
            other => {
                return Err(bad(format!(
                    "dtype {} is not read (uint8, bool, int32, int64, float32, float64 are)",
                    other.descr()
                )));
            }
        };
        let shape: Vec<usize> = header
            .shape()
            .iter()
            .map(|&s| usize::try_from(s).map_err(|_| bad(format!("axis of {s} elements"))))
            .collect::<Result<_>>()?;
        let n = element_count(&shape).ok_or_else(|| bad(format!("shape {shape:?} overflows")))?;
        let supported = matches!(
            (kind, item),
            (TypeChar::Uint, 1)
                | (TypeChar::Bool, 1)
                | (TypeChar::Int, 4)
                | (TypeChar::Int, 8)
                | (TypeChar::Float, 4)
                | (TypeChar::Float, 8)
        );
        if !supported {
            return Err(bad(format!(
                "dtype {} is not read (uint8, bool, int32, int64, float32, float64 are)",
                dtype.descr()
            )));
        }
        let need = n
            .checked_mul(item)
            .ok_or_else(|| bad("size overflows".into()))?;
        // `rest` now starts at the data: exactly shape × item size bytes must follow.
        let have = rest.len();
        if have != need {
            return Err(bad(format!(
                "{} data: shape {shape:?} of {} needs {need} bytes, the file holds {have}",
                if have < need {
                    "truncated"
                } else {
                    "oversized"
                },
                dtype.descr()
            )));
        }
        let file = npyz::NpyFile::with_header(header, rest);
        let data = match kind {
            TypeChar::Uint => NpyData::U8(file.into_vec().map_err(|e| bad(e.to_string()))?),
            TypeChar::Bool => NpyData::Bool(file.into_vec().map_err(|e| bad(e.to_string()))?),
            TypeChar::Int if item == 4 => {
                NpyData::I32(file.into_vec().map_err(|e| bad(e.to_string()))?)
            }
            TypeChar::Int => NpyData::I64(file.into_vec().map_err(|e| bad(e.to_string()))?),
            TypeChar::Float if item == 4 => {
                NpyData::F32(file.into_vec().map_err(|e| bad(e.to_string()))?)
            }
            _ => NpyData::F64(file.into_vec().map_err(|e| bad(e.to_string()))?),
        };
        NpyArray::new(shape, data).map_err(|e| bad(e.to_string()))
    }
}

/// `shape`'s element count, `None` on overflow.
fn element_count(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |n, &s| n.checked_mul(s))
}

/// Writes little-endian whatever the platform (`descr` explicit), so files are the same bytes
/// everywhere.
fn write_typed<T: npyz::Serialize>(
    out: &mut Vec<u8>,
    shape: &[u64],
    descr: &str,
    data: &[T],
) -> std::io::Result<()> {
    let type_str: npyz::TypeStr = descr
        .parse()
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{e}")))?;
    let mut writer = npyz::WriteOptions::<T>::new()
        .dtype(DType::Plain(type_str))
        .shape(shape)
        .writer(out)
        .begin_nd()?;
    for x in data {
        writer.push(x)?;
    }
    writer.finish()
}

/// Reads an `.npy` file.
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    let bytes = read_file(path)?;
    NpyArray::from_npy_bytes(&bytes, &path.display().to_string())
}

/// Writes an `.npy` file atomically.
pub fn write_npy(path: &Path, array: &NpyArray) -> Result<()> {
    AtomicFile::create(path)?.commit(&array.to_npy_bytes())
}

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// An `.npz` archive read into memory: its arrays' names in archive order (the order
/// `np.load(f).items()` gives) and each array on demand.
pub struct Npz {
    path: String,
    zip: zip::ZipArchive<Cursor<Vec<u8>>>,
    /// (array name, index in the zip) of every `.npy` entry, in archive order.
    entries: Vec<(String, usize)>,
}

impl std::fmt::Debug for Npz {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Npz")
            .field("path", &self.path)
            .field("names", &self.names())
            .finish()
    }
}

impl Npz {
    /// Opens an archive: an error unless it is a zip holding at least one `.npy` entry.
    pub fn open(path: &Path) -> Result<Npz> {
        let bytes = read_file(path)?;
        Npz::from_bytes(bytes, &path.display().to_string())
    }

    /// An archive from its bytes; `what` names it in errors.
    pub fn from_bytes(bytes: Vec<u8>, what: &str) -> Result<Npz> {
        let mut zip = zip::ZipArchive::new(Cursor::new(bytes))
            .map_err(|e| Error::Input(format!("{what}: not a NumPy .npz archive ({e})")))?;
        let mut entries = Vec::new();
        for i in 0..zip.len() {
            let file = zip
                .by_index_raw(i)
                .map_err(|e| Error::Input(format!("{what}: unreadable zip entry {i} ({e})")))?;
            if let Some(name) = file.name().strip_suffix(".npy") {
                entries.push((name.to_owned(), i));
            }
        }
        if entries.is_empty() {
            return Err(Error::Input(format!(
                "{what}: an .npz archive with no array in it"
            )));
        }
        Ok(Npz {
            path: what.to_owned(),
            zip,
            entries,
        })
    }

    /// The arrays' names in archive order (`arr_0`, `arr_1`, … for `np.savez(f, a, b)`).
    pub fn names(&self) -> Vec<&str> {
        self.entries.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// The first array in archive order: what SoftRas's loader takes
    /// (`list(np.load(f).items())[0][1]`).
    pub fn first(&mut self) -> Result<NpyArray> {
        let (name, index) = self.entries[0].clone();
        self.read_entry(&name, index)
    }

    /// The array called `name`.
    pub fn array(&mut self, name: &str) -> Result<NpyArray> {
        let Some((_, index)) = self.entries.iter().find(|(n, _)| n == name).cloned() else {
            return Err(Error::Input(format!(
                "{}: no array `{name}` (it holds {})",
                self.path,
                self.names().join(", ")
            )));
        };
        self.read_entry(name, index)
    }

    fn read_entry(&mut self, name: &str, index: usize) -> Result<NpyArray> {
        let what = format!("{}: array `{name}`", self.path);
        let mut file = self
            .zip
            .by_index(index)
            .map_err(|e| Error::Input(format!("{what}: unreadable ({e})")))?;
        let mut bytes = Vec::with_capacity(file.size().min(1 << 30) as usize);
        // The zip crate checks the CRC at the end of the entry, so a corrupted payload is an
        // error here rather than wrong numbers.
        file.read_to_end(&mut bytes)
            .map_err(|e| Error::Input(format!("{what}: corrupted data ({e})")))?;
        NpyArray::from_npy_bytes(&bytes, &what)
    }
}

/// The first array of an `.npz` archive (SoftRas's loader's choice).
pub fn read_npz_first(path: &Path) -> Result<NpyArray> {
    Npz::open(path)?.first()
}

/// The array called `name` of an `.npz` archive.
pub fn read_npz_array(path: &Path, name: &str) -> Result<NpyArray> {
    Npz::open(path)?.array(name)
}

/// The bytes of an `.npz` archive of `arrays` (name, array) in that order, deflated when
/// `compressed` (as `np.savez_compressed`) or stored (as `np.savez`). Deterministic: entries
/// carry a fixed time (1980-01-01, the zip epoch) and mode 0644.
pub fn npz_bytes(arrays: &[(&str, &NpyArray)], compressed: bool) -> Result<Vec<u8>> {
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let method = if compressed {
        zip::CompressionMethod::Deflated
    } else {
        zip::CompressionMethod::Stored
    };
    for (name, array) in arrays {
        if name.is_empty() || name.contains('/') {
            return Err(Error::Input(format!(
                "npz array name `{name}`: not a plain name"
            )));
        }
        let npy = array.to_npy_bytes();
        let options = zip::write::FileOptions::default()
            .compression_method(method)
            .last_modified_time(zip::DateTime::default())
            .unix_permissions(0o644)
            .large_file(npy.len() as u64 >= u64::from(u32::MAX));
        let zip_err = |e: zip::result::ZipError| Error::Input(format!("npz `{name}`: {e}"));
        zip.start_file(format!("{name}.npy"), options)
            .map_err(zip_err)?;
        zip.write_all(&npy)
            .map_err(|e| Error::Input(format!("npz `{name}`: {e}")))?;
    }
    let cursor = zip
        .finish()
        .map_err(|e| Error::Input(format!("npz: {e}")))?;
    Ok(cursor.into_inner())
}

/// Writes an `.npz` archive atomically (see [`npz_bytes`]).
pub fn write_npz(path: &Path, arrays: &[(&str, &NpyArray)], compressed: bool) -> Result<()> {
    let bytes = npz_bytes(arrays, compressed)?;
    AtomicFile::create(path)?.commit(&bytes)
}
