//! Single-view reconstruction as a conditioned implicit field (`recon::field`): the gradient of
//! a training iteration (encoder and shared field through the codes) against central
//! differences of its loss, training lowers the loss and is the same bits at any iterations
//! per submission, reconstruction agrees with the field's twin, and the model file.

mod common;

use softvk::field::cpu as field_cpu;
use softvk::field::voxel::field_occupancy;
use softvk::field::{FieldKind, MlpLayout};
use softvk::fit::AdamOptions;
use softvk::recon::Reconstructor;
use softvk::recon::dataset::{occupancy_to_nmr, voxel_cube};
use softvk::recon::field::{
    FieldNet, FieldReconTrainer, FieldReconTraining, FieldReconstructor, FieldTrainOptions,
    MAX_BATCH, default_probe, field_cube,
};
use softvk::recon::model::ReconModel;
use softvk::recon::train::{LrStep, NetShape, TrainImages, VIEWS};

const SIZE: u32 = 16;

/// Two classes of one object each at 16² (a box and a flat slab).
fn data(ctx: &softvk::gpu::Context) -> TrainImages {
    common::recon::two_objects(ctx, SIZE)
}

fn options() -> FieldTrainOptions {
    FieldTrainOptions {
        net: FieldNet {
            net: NetShape {
                image: SIZE,
                channels: [4, 8, 8],
                latent: 16,
                hidden: 16,
            },
            mlp: MlpLayout {
                hidden_layers: 2,
                width: 16,
                frequencies: 2,
            },
        },
        batch: 2,
        adam: AdamOptions {
            lr: 3e-3,
            ..AdamOptions::default()
        },
        probe: softvk::probe::ProbeSettings {
            rays_per_view: 32,
            anchors: 1024,
            ..default_probe()
        },
        seed: 3,
        ..FieldTrainOptions::default()
    }
}

/// Parameters and gradient of iteration 1 with the learning rate 0 (Adam moves nothing), and
/// its loss, at `params`.
fn loss_at(trainer: &mut FieldReconTrainer<'_>, params: &[f32]) -> f64 {
    trainer
        .trained()
        .write_params(trainer.ctx(), params)
        .unwrap();
    assert_eq!(trainer.run(1, 1, None).unwrap(), None);
    f64::from(trainer.read_log(1).unwrap().silhouette)
}

#[test]
fn an_iterations_gradient_through_the_codes_matches_central_differences() {
    let Some(gpu) = common::gpu() else { return };
    let data = data(&gpu);
    let opts = FieldTrainOptions {
        lr_step: Some(LrStep { at: 1, factor: 0.0 }),
        ..options()
    };
    let mut trainer = FieldReconTraining::fitter(&gpu, &data, &opts, None).unwrap();
    let params = trainer.trained().read_params(&gpu).unwrap();
    let l0 = loss_at(&mut trainer, &params);
    assert!(
        trainer.trained().read_params(&gpu).unwrap() == params,
        "lr 0 moved them"
    );
    let grad = trainer.trained().read_gradient(&gpu).unwrap();
    let e = opts.net.encoder_param_count().unwrap() as usize;
    let mlp = opts.net.mlp;
    // The shared hidden biases are replaced by the codes: their gradient is zero.
    for r in opts.net.code_ranges() {
        assert!(grad[e + r.start..e + r.end].iter().all(|&g| g == 0.0));
    }
    // The largest gradients of: the encoder's code head (reached through the codes alone) and
    // the layer before it, the field's first layer and its output layer. (The convolutions'
    // are too small at the init for an f32 loss's differences.)
    let layers = opts.net.encoder_layers().unwrap();
    let (offsets, _) = softvk::nn::param_offsets(&layers);
    let layer = |l: usize| {
        let start = offsets[l] as usize;
        start..start + layers[l].param_count() as usize
    };
    let head = layer(layers.len() - 1);
    let hidden = layer(layers.len() - 2);
    let (o1, i1, n1) = mlp.layer(0);
    let first = e + o1..e + o1 + i1 * n1;
    let (ol, il, nl) = mlp.layer(mlp.hidden_layers as usize);
    let out = e + ol..e + ol + il * nl + nl;
    let mut checked = 0;
    for (what, range) in [
        ("code head", head),
        ("encoder hidden layer", hidden),
        ("field layer 0", first),
        ("field output", out),
    ] {
        let mut idx: Vec<usize> = range.collect();
        idx.sort_by(|&a, &b| grad[b].abs().total_cmp(&grad[a].abs()));
        for &i in &idx[..2] {
            let g = f64::from(grad[i]);
            let h = 1e-2 * f64::from(params[i].abs()).max(0.1);
            let mut p = params.clone();
            p[i] = (f64::from(params[i]) + h) as f32;
            let plus = loss_at(&mut trainer, &p);
            p[i] = (f64::from(params[i]) - h) as f32;
            let minus = loss_at(&mut trainer, &p);
            let hp = f64::from(p[i]) - f64::from(params[i]);
            let fd = (plus - minus) / (-2.0 * hp);
            eprintln!("{what} [{i}]: gradient {g:.6e}, central difference {fd:.6e}");
            assert!(g != 0.0, "{what}: a zero gradient checks nothing");
            assert!(
                (fd - g).abs() <= 0.05 * g.abs() + 1e-6,
                "{what} [{i}]: gradient {g:e} vs central difference {fd:e}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 8);
    assert!(l0.is_finite() && l0 > 0.0);
}

/// Trains `iterations` with `k` per submission; the parameters' bits and the losses.
fn train_run(
    gpu: &softvk::gpu::Context,
    data: &TrainImages,
    iterations: u32,
    k: u32,
) -> (Vec<u32>, Vec<f32>) {
    let mut trainer = FieldReconTraining::fitter(gpu, data, &options(), None).unwrap();
    let mut losses = Vec::new();
    let mut it = 1;
    while it <= iterations {
        let last = (it + k - 1).min(iterations);
        match trainer.run(it, last, None).unwrap() {
            Some(stopped) => it = stopped,
            None => {
                losses.push(trainer.read_log(last).unwrap().silhouette);
                it = last + 1;
            }
        }
    }
    let bits = trainer
        .trained()
        .read_params(gpu)
        .unwrap()
        .iter()
        .map(|p| p.to_bits())
        .collect();
    (bits, losses)
}

#[test]
fn training_lowers_the_loss_and_is_the_same_bits_at_any_k() {
    let Some(gpu) = common::gpu() else { return };
    let data = data(&gpu);
    let iterations = 40;
    let (params1, losses) = train_run(&gpu, &data, iterations, 1);
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    let (early, late) = (mean(&losses[..8]), mean(&losses[losses.len() - 8..]));
    eprintln!("silhouette loss: first 8 iterations {early:.4}, last 8 {late:.4}");
    assert!(late < 0.7 * early, "the loss did not fall: {losses:?}");
    for k in [7, 40] {
        let (params_k, _) = train_run(&gpu, &data, iterations, k);
        assert!(
            params_k == params1,
            "{k} iterations per submission changed the bits"
        );
    }
}

#[test]
fn reconstruction_is_the_twins_field_and_the_model_round_trips() {
    let Some(gpu) = common::gpu() else { return };
    let data = data(&gpu);
    let opts = options();
    let mut trainer = FieldReconTraining::fitter(&gpu, &data, &opts, None).unwrap();
    assert_eq!(trainer.run(1, 30, None).unwrap(), None);
    let model = ReconModel {
        net: opts.net.net,
        field: Some(opts.net.mlp),
        params: trainer.trained().read_params(&gpu).unwrap(),
        iteration: 30,
    };
    let dir = common::TempDir::new("recon-field-model");
    let path = dir.path("field.npz");
    model.save(&path).unwrap();
    let loaded = ReconModel::load(&path).unwrap();
    assert_eq!(loaded, model);
    assert!(matches!(
        Reconstructor::new(&gpu, &loaded, 1),
        Err(softvk::Error::Input(_))
    ));
    let recon = FieldReconstructor::new(&gpu, &loaded, 4).unwrap();
    // The box's view 0 and the slab's view 5.
    let per = VIEWS as usize * 4 * (SIZE * SIZE) as usize;
    let view = |n: usize, v: usize| {
        let px = 4 * (SIZE * SIZE) as usize;
        &data.images[n * per + v * px..n * per + (v + 1) * px]
    };
    let images: Vec<u8> = [view(0, 0), view(1, 5)].concat();
    let codes = recon.codes(&gpu, &images).unwrap();
    assert_eq!(codes.len(), 2);
    assert!(codes[0] != codes[1], "two images, one code");
    let occ = recon.occupancy(&gpu, &images).unwrap();
    let e = opts.net.encoder_param_count().unwrap() as usize;
    let kind = FieldKind::Mlp {
        hidden_layers: opts.net.mlp.hidden_layers,
        width: opts.net.mlp.width,
        frequencies: opts.net.mlp.frequencies,
    };
    for (code, occ) in codes.iter().zip(&occ) {
        let params: Vec<f64> = opts
            .net
            .object_field(&model.params[e..], code)
            .unwrap()
            .iter()
            .map(|&p| f64::from(p))
            .collect();
        // The same voxels as the library's field occupancy in the dataset's order.
        let field = recon.field_of(&gpu, code).unwrap();
        let lib =
            occupancy_to_nmr(&field_occupancy(&gpu, field, &voxel_cube(), 32).unwrap()).unwrap();
        assert!(&lib == occ, "voxel order or field differs");
        // And the twin's φ at the voxel centres, away from 0.5.
        let mut compared = 0;
        for (i, &inside) in occ.iter().enumerate() {
            let c = softvk::recon::voxel_center(i / 1024, (i / 32) % 32, i % 32);
            let phi = field_cpu::eval(&kind, &field_cube(), &params, c);
            if (phi - 0.5).abs() > 1e-4 {
                assert_eq!(inside, phi > 0.5, "voxel {i}: twin φ {phi}");
                compared += 1;
            }
        }
        assert!(compared > 30_000);
        let inside = occ.iter().filter(|&&x| x).count();
        eprintln!("occupied voxels: {inside}");
    }
    let iso = recon.isosurface(&gpu, view(0, 0), 24).unwrap();
    eprintln!("isosurface: {} triangles", iso.faces.len());
    // Wrong files and misuse.
    let short = ReconModel {
        params: model.params[1..].to_vec(),
        ..model.clone()
    };
    short.save(&path).unwrap();
    assert!(matches!(
        ReconModel::load(&path),
        Err(softvk::Error::Input(_))
    ));
    let mesh_model = ReconModel {
        field: None,
        ..model.clone()
    };
    assert!(matches!(
        FieldReconstructor::new(&gpu, &mesh_model, 1),
        Err(softvk::Error::Input(_))
    ));
    assert!(matches!(
        recon.codes(&gpu, &images[1..]),
        Err(softvk::Error::Input(_))
    ));
}

#[test]
fn the_largest_batch_runs_and_one_more_is_an_input_error() {
    let Some(gpu) = common::gpu() else { return };
    let data = data(&gpu);
    let opts = FieldTrainOptions {
        batch: MAX_BATCH,
        ..options()
    };
    let mut trainer = FieldReconTraining::fitter(&gpu, &data, &opts, None).unwrap();
    assert_eq!(trainer.run(1, 1, None).unwrap(), None);
    for bad in [
        FieldTrainOptions {
            batch: MAX_BATCH + 1,
            ..options()
        },
        FieldTrainOptions {
            batch: 0,
            ..options()
        },
        FieldTrainOptions {
            probe: softvk::probe::ProbeSettings {
                geo_lambda: 0.1,
                ..options().probe
            },
            ..options()
        },
        FieldTrainOptions {
            probe: softvk::probe::ProbeSettings {
                cube_half: 1.0,
                ..options().probe
            },
            ..options()
        },
    ] {
        assert!(matches!(
            FieldReconTraining::fitter(&gpu, &data, &bad, None),
            Err(softvk::Error::Input(_))
        ));
    }
}
