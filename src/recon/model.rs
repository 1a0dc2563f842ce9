//! A trained reconstruction model on disk, and reconstruction with it on the GPU.
//!
//! **The file** is an `.npz` (numpy can open it: `np.load("model.npz")`), written atomically:
//!
//! | array | dtype | what |
//! |---|---|---|
//! | `format` | int32 (1) | [`FORMAT`] |
//! | `net` | int32 (6) | [`NetShape`]: image, channels ×3, latent, hidden |
//! | `field` | int32 (3) | a conditioned-field model only ([`super::field`]): the MLP's hidden layers, width, frequencies |
//! | `params` | float32 (P) | the network's parameters, [`crate::nn::Sequential`]'s layout (a field model: then the MLP's) |
//! | `iteration` | int32 (1) | iterations trained |
//!
//! [`ReconModel::load`] checks every shape. A training run's checkpoints are not models: they
//! are the one checkpoint format of every fit and trainer ([`super::session`]).

use std::ops::Range;
use std::path::Path;

use super::decode::MeshDecoder;
use super::npz::{NpyArray, NpyData, Npz, npz_bytes};
use super::train::NetShape;
use crate::atomic_file::AtomicFile;
use crate::error::{Error, Result};
use crate::field::MlpLayout;
use crate::gpu::{Buffer, Context, MemoryKind};
use crate::nn::{Layer, Sequential};

/// The file format's version: 3 since the colour head is the colour generator (sampled from
/// the input image; format 2 regressed colours, with another head width), 2 since the mesh
/// decoder's centroid is SoftRas's `tanh(0.1 r)` (format 1 squashed it twice) and the settings
/// name the recipe.
pub const FORMAT: i32 = 3;

/// The length of a training run's settings ([`super::train::TrainOptions::settings`]).
pub const SETTINGS: usize = 12;

/// The shape of a conditioned-field network: the encoder ([`NetShape`], whose head predicts the
/// codes) and the occupancy MLP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldNet {
    /// The encoder (its `hidden` layer feeds the code head).
    pub net: NetShape,
    /// The shared occupancy MLP.
    pub mlp: MlpLayout,
}

impl Default for FieldNet {
    /// The default encoder and a 3 × 32 MLP with 3 encoding frequencies (RESULTS.md: a wider
    /// MLP's per-point loops cost llvmpipe 2.5× the iteration at 3 × 64).
    fn default() -> Self {
        Self {
            net: NetShape::default(),
            mlp: MlpLayout {
                hidden_layers: 3,
                width: 32,
                frequencies: 3,
            },
        }
    }
}

impl FieldNet {
    /// Floats of one object's code: every hidden layer's bias, `L · W`.
    pub fn code_len(&self) -> u64 {
        u64::from(self.mlp.hidden_layers) * u64::from(self.mlp.width)
    }

    /// The encoder's layers, its head giving [`FieldNet::code_len`] values.
    pub fn encoder_layers(&self) -> Result<Vec<Layer>> {
        self.mlp.validate()?;
        self.net.layers(self.code_len())
    }

    /// The encoder's parameter count.
    pub fn encoder_param_count(&self) -> Result<u64> {
        Ok(crate::nn::param_offsets(&self.encoder_layers()?).1)
    }

    /// All parameters: the encoder's, then the field's.
    pub fn param_count(&self) -> Result<u64> {
        Ok(self.encoder_param_count()? + self.mlp.param_count() as u64)
    }

    /// The seeded initial parameters: the encoder's PyTorch-like init, then the MLP's.
    pub fn init(&self, seed: u64) -> Result<Vec<f32>> {
        let mut p = crate::nn::init(&self.encoder_layers()?, seed);
        p.extend(self.mlp.initial_params(seed));
        Ok(p)
    }

    /// The field-parameter ranges the code replaces: hidden layer l's bias is
    /// `code[l W .. (l + 1) W]`.
    pub fn code_ranges(&self) -> Vec<Range<usize>> {
        (0..self.mlp.hidden_layers as usize)
            .map(|l| {
                let (offset, inputs, outputs) = self.mlp.layer(l);
                let start = offset + inputs * outputs;
                start..start + outputs
            })
            .collect()
    }

    /// One object's field parameters: the shared ones (`field`, [`MlpLayout::param_count`]
    /// floats) with its code copied into the hidden biases.
    pub fn object_field(&self, field: &[f32], code: &[f32]) -> Result<Vec<f32>> {
        let w = self.mlp.width as usize;
        if field.len() != self.mlp.param_count() || code.len() as u64 != self.code_len() {
            return Err(Error::Input(format!(
                "a conditioned field of {} shared parameters and a code of {}: need {} and {}",
                field.len(),
                code.len(),
                self.mlp.param_count(),
                self.code_len()
            )));
        }
        let mut p = field.to_vec();
        for (l, r) in self.code_ranges().into_iter().enumerate() {
            p[r].copy_from_slice(&code[l * w..(l + 1) * w]);
        }
        Ok(p)
    }
}

/// A reconstruction network: its shape, its parameters, how long it trained.
#[derive(Clone, Debug, PartialEq)]
pub struct ReconModel {
    /// The network's shape (a field model: its encoder).
    pub net: NetShape,
    /// `Some` for a conditioned-field model ([`super::field`]): the shared occupancy MLP, whose
    /// parameters follow the encoder's in `params`.
    pub field: Option<MlpLayout>,
    /// Its parameters.
    pub params: Vec<f32>,
    /// Iterations trained.
    pub iteration: u32,
}

impl ReconModel {
    /// Writes the model atomically (nothing half-written if interrupted).
    pub fn save(&self, path: &Path) -> Result<()> {
        let n = self.net;
        let i32s = |v: Vec<i32>| NpyArray::new(vec![v.len()], NpyData::I32(v));
        let f32s = |v: &[f32]| NpyArray::new(vec![v.len()], NpyData::F32(v.to_vec()));
        let format = i32s(vec![FORMAT])?;
        let net = i32s(
            [
                n.image,
                n.channels[0],
                n.channels[1],
                n.channels[2],
                n.latent,
                n.hidden,
            ]
            .iter()
            .map(|&x| x as i32)
            .collect(),
        )?;
        let params = f32s(&self.params)?;
        let iteration = i32s(vec![self.iteration as i32])?;
        let mut arrays: Vec<(&str, NpyArray)> = vec![
            ("format", format),
            ("net", net),
            ("params", params),
            ("iteration", iteration),
        ];
        if let Some(m) = self.field {
            arrays.push((
                "field",
                i32s(
                    [m.hidden_layers, m.width, m.frequencies]
                        .iter()
                        .map(|&x| x as i32)
                        .collect(),
                )?,
            ));
        }
        let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
        let bytes = npz_bytes(&refs, false)?;
        AtomicFile::create(path)?.commit(&bytes)
    }

    /// Reads a model, checking the format, the shapes and the parameter count.
    pub fn load(path: &Path) -> Result<ReconModel> {
        let bad = |what: String| Error::Input(format!("{}: {what}", path.display()));
        let mut npz = Npz::open(path)?;
        let ints = |a: NpyArray, name: &str| match a.data {
            NpyData::I32(v) => Ok(v),
            _ => Err(bad(format!("`{name}` is not int32"))),
        };
        let floats = |a: NpyArray, name: &str| match a.data {
            NpyData::F32(v) => Ok(v),
            _ => Err(bad(format!("`{name}` is not float32"))),
        };
        let format = ints(npz.array("format")?, "format")?;
        if format != [FORMAT] {
            return Err(bad(format!(
                "model format {format:?}; this softvk reads format {FORMAT}"
            )));
        }
        let net = ints(npz.array("net")?, "net")?;
        let Ok::<[i32; 6], _>([image, c0, c1, c2, latent, hidden]) = net.clone().try_into() else {
            return Err(bad(format!("`net` holds {} values, not 6", net.len())));
        };
        let positive = |x: i32| u32::try_from(x).ok().filter(|&x| x > 0);
        let shape = match [image, c0, c1, c2, latent, hidden].map(positive) {
            [
                Some(image),
                Some(a),
                Some(b),
                Some(c),
                Some(latent),
                Some(hidden),
            ] => NetShape {
                image,
                channels: [a, b, c],
                latent,
                hidden,
            },
            _ => return Err(bad(format!("network shape {net:?}"))),
        };
        let field = if npz.names().contains(&"field") {
            let f = ints(npz.array("field")?, "field")?;
            let layout = match f[..] {
                [l, w, freqs] if l > 0 && w > 0 && freqs >= 0 => MlpLayout {
                    hidden_layers: l as u32,
                    width: w as u32,
                    frequencies: freqs as u32,
                },
                _ => return Err(bad(format!("field shape {f:?}"))),
            };
            layout
                .validate()
                .map_err(|e| bad(format!("field shape {f:?}: {e}")))?;
            Some(layout)
        } else {
            None
        };
        let params = floats(npz.array("params")?, "params")?;
        let expected = match field {
            Some(mlp) => FieldNet { net: shape, mlp }.param_count()?,
            None => super::train::param_count(&shape)?,
        };
        if params.len() as u64 != expected {
            return Err(bad(format!(
                "{} parameters for a network {shape:?} of {expected}",
                params.len()
            )));
        }
        if let Some(i) = params.iter().position(|p| !p.is_finite()) {
            return Err(bad(format!("parameter {i} is not finite")));
        }
        let iteration = ints(npz.array("iteration")?, "iteration")?;
        let iteration = match iteration.as_slice() {
            [i] if *i >= 0 => *i as u32,
            _ => return Err(bad(format!("iteration {iteration:?}"))),
        };
        Ok(ReconModel {
            net: shape,
            field,
            params,
            iteration,
        })
    }
}

/// `images` (uint8 RGBA planes, `4 × image²` bytes each, at most `capacity` of them) as the
/// network's input floats, as the batch gather converts them (the byte times the f32 nearest
/// 1/255); with their count.
pub(crate) fn input_floats(images: &[u8], image: u32, capacity: u32) -> Result<(usize, Vec<f32>)> {
    let per = 4 * (image as usize).pow(2);
    if images.is_empty() || images.len() % per != 0 {
        return Err(Error::Input(format!(
            "{} image bytes: a whole number of {image}×{image} RGBA images, at least one",
            images.len(),
        )));
    }
    let n = images.len() / per;
    if n > capacity as usize {
        return Err(Error::Input(format!(
            "{n} images for a reconstructor of {capacity}"
        )));
    }
    let scale = 1.0f32 / 255.0;
    Ok((n, images.iter().map(|&b| f32::from(b) * scale).collect()))
}

/// One reconstructed mesh: positions of the template's vertices ([`super::train::template`]'s
/// faces) and their colours.
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Vertex colours (RGB in [0, 1]).
    pub colors: Vec<[f32; 3]>,
}

/// Reconstruction on the GPU: the network and the decoder's mesh head, forward only, for
/// batches of up to a capacity of images.
pub struct Reconstructor {
    net: Sequential,
    decoder: MeshDecoder,
    params: Buffer,
    input: Buffer,
    identity: Buffer,
    meshes: Buffer,
    copies: Buffer,
    colors: Buffer,
    pooled: Buffer,
    palette: Buffer,
    capacity: u32,
    image: u32,
}

impl Reconstructor {
    /// Uploads `model` for batches of up to `capacity` images.
    pub fn new(ctx: &Context, model: &ReconModel, capacity: u32) -> Result<Self> {
        if model.field.is_some() {
            return Err(Error::Input(
                "a conditioned-field model: reconstruct with recon::field::FieldReconstructor"
                    .into(),
            ));
        }
        if capacity == 0 {
            return Err(Error::Input("a reconstruction batch of 0 images".into()));
        }
        let t = super::train::template();
        let decoder = MeshDecoder::new(ctx, &t.positions, model.net.image)?;
        let net = Sequential::new(
            ctx,
            &model.net.layers(decoder.outputs_per_object())?,
            capacity,
        )?;
        if model.params.len() as u64 != net.param_count() {
            return Err(Error::Input(format!(
                "{} parameters for a network of {}",
                model.params.len(),
                net.param_count()
            )));
        }
        let (b, v) = (u64::from(capacity), t.vertex_count() as u64);
        let px = u64::from(model.net.image) * u64::from(model.net.image);
        let device =
            |name: &str, floats: u64| ctx.create_buffer(name, 4 * floats, MemoryKind::Device);
        Ok(Self {
            params: ctx.upload_buffer("recon params", &model.params)?,
            input: device("recon input", 4 * b * px)?,
            identity: ctx.upload_buffer(
                "recon identity rotations",
                &vec![[1.0f32, 0.0]; capacity as usize],
            )?,
            meshes: device("recon meshes", 3 * b * v)?,
            copies: device("recon copies", 3 * b * v)?,
            colors: device("recon colours", 4 * b * v)?,
            pooled: device(
                "recon pooled cells",
                decoder.color_generator().pooled_floats(capacity),
            )?,
            palette: device(
                "recon palettes",
                decoder.color_generator().palette_floats(capacity),
            )?,
            net,
            decoder,
            capacity,
            image: model.net.image,
        })
    }

    /// The meshes the network predicts from `images` (one per image): uint8 RGBA planes
    /// (`4 × H × W` per image, the NMR layout), at most the capacity.
    pub fn reconstruct(&self, ctx: &Context, images: &[u8]) -> Result<Vec<Reconstruction>> {
        let (n, input) = input_floats(images, self.image, self.capacity)?;
        ctx.write_buffer(&self.input, 0, &input)?;
        ctx.submit_and_wait(|rec| {
            self.net
                .record_forward(rec, self.params.whole(), self.input.whole(), n as u32)?;
            self.decoder.record_forward(
                rec,
                n as u32,
                1,
                self.net.output().whole(),
                self.identity.whole(),
                self.meshes.whole(),
                self.copies.whole(),
            )?;
            self.decoder.record_colors(
                rec,
                n as u32,
                1,
                self.net.output().whole(),
                self.input.whole(),
                self.pooled.whole(),
                self.palette.whole(),
                self.colors.whole(),
            )
        })?;
        let v = self.decoder.vertex_count() as usize;
        let flat: Vec<[f32; 3]> = ctx.read_buffer(&self.meshes, 0, n * v)?;
        let colors: Vec<[f32; 4]> = ctx.read_buffer(&self.colors, 0, n * v)?;
        Ok(flat
            .chunks(v)
            .zip(colors.chunks(v))
            .map(|(p, c)| Reconstruction {
                positions: p.to_vec(),
                colors: c.iter().map(|c| [c[0], c[1], c[2]]).collect(),
            })
            .collect())
    }

    /// Images per batch at most.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}
