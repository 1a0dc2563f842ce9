//! Checkpoints of a fit's complete state, on disk: what a session ([`super::session`]) writes
//! for `--checkpoint DIR` and reads back for `--resume DIR`, so that a fit stopped at a
//! checkpoint and resumed ends bit for bit as the uninterrupted fit (softvk is deterministic).
//! Every fit and trainer has this one format; its payload is the session's log and
//! validations, then the fit's state
//! ([`super::session::Trainee::save_state`]).
//!
//! The file is a small explicit binary format, written by hand rather than through serde and a
//! binary codec: it is a handful of little-endian numbers and `f32` arrays, and what matters is
//! the checks on reading (magic, format, the softvk version that wrote it, the kind of fit, a
//! fingerprint of the fit's inputs), each refused with one clear line. Layout:
//!
//! ```text
//! b"SOFTVKCK", format u32, version (u32 length + UTF-8), kind u32, fingerprint u64,
//! iteration u32, seconds f64, then the payload: the log (its columns, then the rows:
//! [`super::log::write_log`]), the
//! validations (u32 count, then u32 iteration and f64 score each) and the fit's state (arrays
//! as u64 length + values), then a checksum u64 (FNV-1a of every byte before it)
//! ```
//!
//! The checksum refuses a damaged or truncated file before anything in it is believed; the
//! readers refuse non-finite parameters and moments besides, whatever wrote them.

use std::path::Path;

use super::Adam;
use crate::atomic_file::AtomicFile;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context};

const MAGIC: &[u8; 8] = b"SOFTVKCK";
/// The format this softvk writes and reads: 4 since the log is stored by its columns
/// ([`super::log`]).
const FORMAT: u32 = 4;

/// The kind of fit a checkpoint belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitKind {
    /// `fit-mesh` (and `demo`).
    Mesh = 1,
    /// `fit-field`.
    Field = 2,
    /// `fit-pose`.
    Pose = 3,
    /// `fit-articulated`.
    Articulated = 4,
    /// `train-recon`: the mesh network.
    ReconMesh = 5,
    /// `train-recon --field`: the conditioned field.
    ReconField = 6,
}

impl FitKind {
    fn name(code: u32) -> &'static str {
        match code {
            1 => "mesh fit",
            2 => "field fit",
            3 => "pose fit",
            4 => "articulated fit",
            5 => "mesh network training",
            6 => "conditioned field training",
            _ => "unknown fit",
        }
    }
}

/// FNV-1a, 64 bits: a fingerprint of a fit's inputs, stable across platforms and Rust versions
/// (unlike `std`'s hasher). Not a cryptographic hash: it tells a checkpoint of other inputs
/// apart, it does not authenticate one.
#[derive(Clone, Copy, Debug)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fingerprint {
    /// Adds bytes.
    pub fn add(&mut self, bytes: &[u8]) -> &mut Self {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
        self
    }

    /// Adds plain data (numbers, arrays of them) by their bytes.
    pub fn add_pod<T: bytemuck::Pod>(&mut self, data: &[T]) -> &mut Self {
        self.add(bytemuck::cast_slice(data))
    }

    /// The value.
    pub fn value(&self) -> u64 {
        self.0
    }
}

/// A checkpoint's header and payload bytes, as written or read.
pub struct Checkpoint {
    /// The kind of fit.
    pub kind: FitKind,
    /// The fingerprint of the fit's inputs.
    pub fingerprint: u64,
    /// Iterations done.
    pub iteration: u32,
    /// Seconds the fit had run.
    pub seconds: f64,
    /// The kind's payload ([`Writer`] / [`Reader`]).
    pub payload: Vec<u8>,
}

impl Checkpoint {
    /// Writes the checkpoint to `path` atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut w = Writer::default();
        w.bytes(MAGIC);
        w.u32(FORMAT);
        let version = env!("CARGO_PKG_VERSION").as_bytes();
        w.u32(version.len() as u32);
        w.bytes(version);
        w.u32(self.kind as u32);
        w.u64(self.fingerprint);
        w.u32(self.iteration);
        w.f64(self.seconds);
        w.bytes(&self.payload);
        let checksum = Fingerprint::default().add(&w.0).value();
        w.u64(checksum);
        AtomicFile::create(path)?.commit(&w.0)
    }

    /// Reads a checkpoint of `kind` for inputs of `fingerprint` from `path`; anything else (not
    /// a checkpoint, another format or softvk version, another kind of fit, other inputs) is a
    /// clear error.
    pub fn read(path: &Path, kind: FitKind, fingerprint: u64) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let bad = |why: &str| Error::Input(format!("{}: {why}", path.display()));
        if bytes.get(..8) != Some(&MAGIC[..]) {
            return Err(bad("not a softvk checkpoint"));
        }
        // The checksum first: nothing of a damaged file is believed, not even its format.
        let (body, sum) = bytes.split_at(bytes.len().max(16) - 8);
        let sum: [u8; 8] = sum.try_into().map_err(|_| bad("truncated checkpoint"))?;
        if Fingerprint::default().add(body).value() != u64::from_le_bytes(sum) {
            return Err(bad(
                "damaged or truncated checkpoint (its checksum does not match)",
            ));
        }
        let mut r = Reader { bytes: body, at: 8 };
        let format = r.u32().map_err(|_| bad("truncated checkpoint"))?;
        if format != FORMAT {
            return Err(bad(&format!(
                "checkpoint format {format}, this softvk reads format {FORMAT} (written by \
                 another softvk: start the fit again, or resume it with the softvk that wrote it)"
            )));
        }
        let len = r.u32().map_err(|_| bad("truncated checkpoint"))? as usize;
        let version = r.take(len).map_err(|_| bad("truncated checkpoint"))?;
        let version = String::from_utf8_lossy(version).into_owned();
        if version != env!("CARGO_PKG_VERSION") {
            return Err(bad(&format!(
                "checkpoint written by softvk {version}, this is softvk {}",
                env!("CARGO_PKG_VERSION")
            )));
        }
        let code = r.u32().map_err(|_| bad("truncated checkpoint"))?;
        if code != kind as u32 {
            return Err(bad(&format!(
                "a {} checkpoint, not a {}'s",
                FitKind::name(code),
                FitKind::name(kind as u32)
            )));
        }
        let found = r.u64().map_err(|_| bad("truncated checkpoint"))?;
        if found != fingerprint {
            return Err(bad(
                "checkpoint of another fit: its template, targets, cameras or options differ",
            ));
        }
        let iteration = r.u32().map_err(|_| bad("truncated checkpoint"))?;
        let seconds = r.f64().map_err(|_| bad("truncated checkpoint"))?;
        Ok(Checkpoint {
            kind,
            fingerprint,
            iteration,
            seconds,
            payload: r.bytes[r.at..].to_vec(),
        })
    }
}

/// Little-endian writer of a payload.
#[derive(Default)]
pub struct Writer(pub Vec<u8>);

impl Writer {
    /// Raw bytes.
    pub fn bytes(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
    /// A u32.
    pub fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    /// A u64.
    pub fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    /// An f32.
    pub fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
    /// An f64.
    pub fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
    /// An array of f32: its length (u64), then the values.
    pub fn f32s(&mut self, v: &[f32]) {
        self.u64(v.len() as u64);
        for x in v {
            self.f32(*x);
        }
    }
}

/// Little-endian reader of a payload; every read fails cleanly past the end.
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// Reads `payload`.
    pub fn new(payload: &'a [u8]) -> Self {
        Self {
            bytes: payload,
            at: 0,
        }
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| Error::Input("truncated checkpoint".into()))?;
        let b = &self.bytes[self.at..end];
        self.at = end;
        Ok(b)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("N bytes"))
    }

    /// A u32.
    pub fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    /// A u64.
    pub fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    /// An f32.
    pub fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    /// An f64.
    pub fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    /// An array of f32 written by [`Writer::f32s`], of at most `max` values.
    pub fn f32s(&mut self, max: usize) -> Result<Vec<f32>> {
        let n = self.u64()?;
        if n > max as u64 {
            return Err(Error::Input(format!(
                "checkpoint array of {n} values, at most {max} expected"
            )));
        }
        (0..n).map(|_| self.f32()).collect()
    }
    /// The bytes not read yet.
    pub fn rest(&self) -> &'a [u8] {
        &self.bytes[self.at..]
    }
    /// Whether every byte was read.
    pub fn done(&self) -> bool {
        self.at == self.bytes.len()
    }
}

/// Writes the parameters in `params` and the moments of `adam` (`n` values each), read from
/// the device: the state of a fit whose optimizer is one Adam over a flat parameter vector.
pub fn save_adam(
    ctx: &Context,
    params: &Buffer,
    adam: &Adam,
    n: usize,
    w: &mut Writer,
) -> Result<()> {
    let (m, v) = adam.moments();
    w.f32s(&ctx.read_buffer::<f32>(params, 0, n)?);
    w.f32s(&ctx.read_buffer::<f32>(m, 0, n)?);
    w.f32s(&ctx.read_buffer::<f32>(v, 0, n)?);
    Ok(())
}

/// Reads what [`save_adam`] wrote, checking that each array holds `n` values (`what`: whose
/// parameters, for the error) and that the state is finite ([`check_state`]): the parameters
/// and the two moments.
pub fn read_adam(r: &mut Reader<'_>, n: usize, what: &str) -> Result<[Vec<f32>; 3]> {
    let (p, m, v) = (r.f32s(n)?, r.f32s(n)?, r.f32s(n)?);
    if [&p, &m, &v].iter().any(|a| a.len() != n) {
        return Err(Error::Input(format!(
            "resume: the state has {} parameters, {what} {n}",
            p.len()
        )));
    }
    check_state(&p, &m, &v)?;
    Ok([p, m, v])
}

/// Reads what [`save_adam`] wrote ([`read_adam`]) and puts it back on the device.
pub fn restore_adam(
    ctx: &Context,
    params: &Buffer,
    adam: &Adam,
    n: usize,
    r: &mut Reader<'_>,
    what: &str,
) -> Result<()> {
    let [p, m, v] = read_adam(r, n, what)?;
    let (dm, dv) = adam.moments();
    ctx.write_buffer(params, 0, &p)?;
    ctx.write_buffer(dm, 0, &m)?;
    ctx.write_buffer(dv, 0, &v)
}

/// Writes `N` f64 parameters and their two moments (an optimizer state kept in f64: the pose
/// fit's).
pub fn write_f64_state<const N: usize>(w: &mut Writer, state: &[[f64; N]; 3]) {
    for a in state {
        for &x in a {
            w.f64(x);
        }
    }
}

/// Reads what [`write_f64_state`] wrote, checked by [`check_state`].
pub fn read_f64_state<const N: usize>(r: &mut Reader<'_>) -> Result<[[f64; N]; 3]> {
    let mut state = [[0.0; N]; 3];
    for a in &mut state {
        for x in a.iter_mut() {
            *x = r.f64()?;
        }
    }
    check_state(&state[0], &state[1], &state[2])?;
    Ok(state)
}

/// Refuses an optimizer state with a non-finite parameter or moment, or a negative second
/// moment (Adam's `v` is a mean of squares).
pub fn check_state<T: Copy + Into<f64>>(params: &[T], m: &[T], v: &[T]) -> Result<()> {
    let finite = |a: &[T]| a.iter().all(|&x| x.into().is_finite());
    if !(finite(params) && finite(m) && finite(v)) || v.iter().any(|&x| x.into() < 0.0) {
        return Err(Error::Input(
            "checkpoint holds a non-finite parameter or moment, or a negative second moment".into(),
        ));
    }
    Ok(())
}
