//! The fit kernels against their f64 twins, on lavapipe with validation on: losses, gradients,
//! accumulation, a whole recorded iteration, bit-identical repeats, and bad input as errors.
//!
//! **Tolerance.** The twins get the very `f32` inputs the GPU gets (widened exactly), so every
//! difference is the GPU's f32 rounding. The deepest chains here are the reductions: at most a
//! few hundred terms summed sequentially per invocation, then 8 tree levels, a relative error
//! bound of about (k + 8)·2⁻²⁴ ≈ 1e-5 of the sum of magnitudes in the worst case and ~√k·2⁻²⁴
//! typically. So each output is compared within 1e-5 × its largest twin component (and the
//! measured worst ratio is printed); the flatten gradient, whose epsilons and 1/sin factors
//! amplify rounding on nearly flat edges, gets the same bound and meets it.

mod common;

use softvk::fit::{
    Adam, AdamOptions, Deform, GradOut, ImageMse, Regularizers, SilhouetteLoss, adam, blur, deform,
    flatten, laplacian, silhouette,
};
use softvk::gpu::{Buffer, Context, MemoryKind};
use softvk::mesh::Mesh;
use softvk::{Error, LimitKind};

use rand::RngExt;

const REL: f64 = 1e-5;

/// Worst |gpu − twin| / max|twin|; fails above `rel`.
fn assert_close(what: &str, gpu: &[f32], twin: &[f64], rel: f64) {
    assert_eq!(gpu.len(), twin.len(), "{what}: lengths");
    let scale = twin
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    let (worst, at) = gpu
        .iter()
        .zip(twin)
        .map(|(&g, &t)| (f64::from(g) - t).abs())
        .enumerate()
        .fold(
            (0.0, 0),
            |(w, wi), (i, e)| if e > w { (e, i) } else { (w, wi) },
        );
    eprintln!(
        "{what}: worst error {:.2e} of the largest component",
        worst / scale
    );
    assert!(
        worst <= rel * scale,
        "{what}: element {at}: GPU {} vs twin {} (scale {scale:e})",
        gpu[at],
        twin[at]
    );
}

fn widen(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

fn widen4(v: &[[f32; 4]]) -> Vec<[f64; 4]> {
    v.iter().map(|p| p.map(f64::from)).collect()
}

fn read_f32(ctx: &Context, buffer: &Buffer, n: usize) -> Vec<f32> {
    ctx.read_buffer(buffer, 0, n).unwrap()
}

fn random_rgba(rng: &mut rand_pcg::Pcg64, n: usize) -> Vec<[f32; 4]> {
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(0.0..1.0f32)))
        .collect()
}

/// A jittered icosphere scaled into the deformation's open cube, no coordinate zero.
fn template(subdivisions: u32, seed: u64) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mesh = Mesh::icosphere(subdivisions);
    let mut rng = common::rng(seed);
    let positions = mesh
        .positions
        .iter()
        .map(|p| p.map(|v| 0.5 * v + rng.random_range(0.003..0.03f32)))
        .collect();
    (positions, mesh.faces)
}

#[test]
fn silhouette_loss_matches_its_twin_and_accumulates_into_d_image() {
    let Some(gpu) = common::gpu() else { return };
    let mut rng = common::rng(1);
    // Views smaller than a workgroup and larger than one (the strided loop).
    for (views, w, h) in [(3u32, 13u32, 11u32), (2, 40, 37)] {
        let n = (views * w * h) as usize;
        let images = random_rgba(&mut rng, n);
        let targets: Vec<f32> = (0..n)
            .map(|_| f32::from(rng.random_range(0.0..1.0f32) > 0.4))
            .collect();
        let old = random_rgba(&mut rng, n);
        let loss = SilhouetteLoss::new(&gpu, views, w, h).unwrap();
        let images_buf = gpu.upload_buffer("images", &images).unwrap();
        let targets_buf = gpu.upload_buffer("targets", &targets).unwrap();
        let d_image = gpu.upload_buffer("d_image", &old).unwrap();
        let d_acc = gpu.upload_buffer("d_image (accumulated)", &old).unwrap();
        gpu.submit_and_wait(|rec| {
            let (i, t) = (images_buf.whole(), targets_buf.whole());
            loss.record(rec, i, t, Some(GradOut::write(d_image.whole())))?;
            loss.record(rec, i, t, Some(GradOut::accumulate(d_acc.whole(), 0.5)))
        })
        .unwrap();

        let twin = silhouette::cpu::neg_iou(&widen4(&images), &widen(&targets), views as usize);
        let tag = format!("{views}×{w}×{h}");
        assert_close(
            &format!("IoU loss {tag}"),
            &[loss.read_loss(&gpu).unwrap()],
            &[twin.loss],
            REL,
        );
        assert_close(
            &format!("IoUs {tag}"),
            &loss.read_ious(&gpu).unwrap(),
            &twin.ious,
            REL,
        );
        let d: Vec<[f32; 4]> = gpu.read_buffer(&d_image, 0, n).unwrap();
        assert!(d.iter().all(|p| p[..3] == [0.0; 3]), "RGB gradients are 0");
        let flat = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let twin_d: Vec<f64> = twin.d_image.iter().flatten().copied().collect();
        assert_close(&format!("dL/dP {tag}"), &flat(&d), &twin_d, REL);
        let acc: Vec<[f32; 4]> = gpu.read_buffer(&d_acc, 0, n).unwrap();
        let twin_acc: Vec<f64> = twin
            .d_image
            .iter()
            .zip(&old)
            .flat_map(|(g, o)| (0..4).map(move |c| f64::from(o[c]) + 0.5 * g[c]))
            .collect();
        assert_close(
            &format!("accumulated dL/dP {tag}"),
            &flat(&acc),
            &twin_acc,
            REL,
        );
    }
}

#[test]
fn image_mse_matches_its_twin() {
    let Some(gpu) = common::gpu() else { return };
    let mut rng = common::rng(2);
    let (views, w, h) = (2u32, 23u32, 17u32);
    let n = (views * w * h) as usize;
    let images = random_rgba(&mut rng, n);
    let targets = random_rgba(&mut rng, n);
    let mse = ImageMse::new(&gpu, views, w, h).unwrap();
    let images_buf = gpu.upload_buffer("images", &images).unwrap();
    let targets_buf = gpu.upload_buffer("targets", &targets).unwrap();
    let d_image = gpu
        .create_buffer("d_image", 16 * n as u64, MemoryKind::Device)
        .unwrap();
    gpu.submit_and_wait(|rec| {
        mse.record(
            rec,
            images_buf.whole(),
            targets_buf.whole(),
            Some(GradOut::write(d_image.whole()).weighted(2.0)),
        )
    })
    .unwrap();
    let (loss, grad) = silhouette::cpu::mse(&widen4(&images), &widen4(&targets));
    assert_close("MSE", &[mse.read_loss(&gpu).unwrap()], &[loss], REL);
    let twin: Vec<f64> = grad.iter().flatten().map(|g| 2.0 * g).collect();
    assert_close("2 × dMSE/dP", &read_f32(&gpu, &d_image, 4 * n), &twin, REL);
}

#[test]
fn blurred_image_mse_matches_its_twin() {
    // Two views of a non-square image, a blur whose taps (radius 6) reach past every border.
    let Some(gpu) = common::gpu() else { return };
    let mut rng = common::rng(3);
    let (views, w, h) = (2u32, 23u32, 17u32);
    let n = (views * w * h) as usize;
    let images = random_rgba(&mut rng, n);
    let targets = random_rgba(&mut rng, n);
    let mse = blur::BlurredMse::new(&gpu, views, w, h).unwrap();
    let images_buf = gpu.upload_buffer("images", &images).unwrap();
    let targets_buf = gpu.upload_buffer("targets", &targets).unwrap();
    let d_image = gpu
        .create_buffer("d_image", 16 * n as u64, MemoryKind::Device)
        .unwrap();
    for std in [0.0, 1.7] {
        gpu.submit_and_wait(|rec| {
            mse.record(
                rec,
                images_buf.whole(),
                targets_buf.whole(),
                Some(d_image.whole()),
                std,
            )
        })
        .unwrap();
        let (loss, grad) = blur::cpu::blurred_mse(&widen4(&images), &widen4(&targets), w, h, std);
        assert_close("blurred MSE", &[mse.read_loss(&gpu).unwrap()], &[loss], REL);
        let twin: Vec<f64> = grad.iter().flatten().copied().collect();
        assert_close(
            "d blurred MSE/dP",
            &read_f32(&gpu, &d_image, 4 * n),
            &twin,
            REL,
        );
    }
    // A blur wider than MAX_BLUR_STD is refused.
    let err = gpu.submit_and_wait(|rec| {
        mse.record(rec, images_buf.whole(), targets_buf.whole(), None, 40.0)
    });
    assert!(matches!(err, Err(Error::Input(_))), "{err:?}");
}

#[test]
fn laplacian_and_flatten_match_their_twins_and_accumulate_with_weights() {
    let Some(gpu) = common::gpu() else { return };
    let (positions, faces) = template(2, 3);
    let v = positions.len();
    let flat: Vec<f32> = positions.iter().flatten().copied().collect();
    let reg = Regularizers::new(&gpu, &faces, v).unwrap();
    let pos = gpu.upload_buffer("positions", &flat).unwrap();
    let lap_grad = gpu
        .create_buffer("laplacian grad", 12 * v as u64, MemoryKind::Device)
        .unwrap();
    let flat_grad = gpu
        .create_buffer("flatten grad", 12 * v as u64, MemoryKind::Device)
        .unwrap();
    let total = gpu
        .create_buffer("weighted grad", 12 * v as u64, MemoryKind::Device)
        .unwrap();
    gpu.submit_and_wait(|rec| {
        reg.record_laplacian(rec, pos.whole(), Some(GradOut::write(lap_grad.whole())))?;
        reg.record_flatten(rec, pos.whole(), Some(GradOut::write(flat_grad.whole())))?;
        // SoftRas's demo weights, summed into one gradient.
        reg.record_laplacian(
            rec,
            pos.whole(),
            Some(GradOut::write(total.whole()).weighted(0.03)),
        )?;
        reg.record_flatten(
            rec,
            pos.whole(),
            Some(GradOut::accumulate(total.whole(), 0.0003)),
        )
    })
    .unwrap();

    let x = widen(&flat);
    let (lap_loss, lap_twin) = laplacian::cpu::loss_and_grad(reg.adjacency(), &x);
    let (flat_loss, flat_twin) = flatten::cpu::loss_and_grad(reg.flatten_edges(), &x);
    let losses = reg.read_losses(&gpu).unwrap();
    assert_close("Laplacian loss", &[losses.laplacian], &[lap_loss], REL);
    assert_close("flatten loss", &[losses.flatten], &[flat_loss], REL);
    assert_close(
        "Laplacian grad",
        &read_f32(&gpu, &lap_grad, 3 * v),
        &lap_twin,
        REL,
    );
    assert_close(
        "flatten grad",
        &read_f32(&gpu, &flat_grad, 3 * v),
        &flat_twin,
        REL,
    );
    let weighted: Vec<f64> = lap_twin
        .iter()
        .zip(&flat_twin)
        .map(|(l, f)| 0.03 * l + 0.0003 * f)
        .collect();
    assert_close(
        "weighted sum",
        &read_f32(&gpu, &total, 3 * v),
        &weighted,
        REL,
    );
}

#[test]
fn a_mesh_without_shared_edges_has_no_flatten_term_but_a_laplacian() {
    let Some(gpu) = common::gpu() else { return };
    // One triangle and an unused vertex: no edge has two faces, vertex 3 has a zero row.
    let reg = Regularizers::new(&gpu, &[[0, 1, 2]], 4).unwrap();
    assert_eq!(reg.flatten_edges().edge_count(), 0);
    let x: [f32; 12] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 5.0, 5.0, 5.0];
    let pos = gpu.upload_buffer("positions", &x).unwrap();
    let grad = gpu.upload_buffer("grad", &[7.0f32; 12]).unwrap();
    gpu.submit_and_wait(|rec| {
        reg.record_flatten(rec, pos.whole(), Some(GradOut::write(grad.whole())))?;
        reg.record_laplacian(
            rec,
            pos.whole(),
            Some(GradOut::accumulate(grad.whole(), 1.0)),
        )
    })
    .unwrap();
    let (lap, lap_grad) = laplacian::cpu::loss_and_grad(reg.adjacency(), &widen(&x));
    let losses = reg.read_losses(&gpu).unwrap();
    assert_eq!(losses.flatten, 0.0);
    assert_close("Laplacian loss", &[losses.laplacian], &[lap], REL);
    let got = read_f32(&gpu, &grad, 12);
    assert_close("Laplacian grad (flatten's is 0)", &got, &lap_grad, REL);
    assert_eq!(&got[9..], &[0.0; 3], "the unused vertex");
}

#[test]
fn deformation_forward_and_backward_match_their_twins() {
    let Some(gpu) = common::gpu() else { return };
    let (t, _) = template(2, 4);
    let v = t.len();
    let mut rng = common::rng(5);
    let params: Vec<f32> = (0..3 * v + 3)
        .map(|_| rng.random_range(-0.7..0.7f32))
        .collect();
    let d_pos: Vec<f32> = (0..3 * v).map(|_| rng.random_range(-1.0..1.0f32)).collect();
    let deform = Deform::new(&gpu, &t).unwrap();
    assert_eq!(deform.param_count(), 3 * v as u64 + 3);
    let params_buf = gpu.upload_buffer("params", &params).unwrap();
    let d_pos_buf = gpu.upload_buffer("d positions", &d_pos).unwrap();
    let pos = gpu
        .create_buffer("positions", 12 * v as u64, MemoryKind::Device)
        .unwrap();
    let d_params = gpu
        .create_buffer("d params", 4 * (3 * v as u64 + 3), MemoryKind::Device)
        .unwrap();
    gpu.submit_and_wait(|rec| {
        deform.record_forward(rec, params_buf.whole(), pos.whole())?;
        deform.record_backward(rec, params_buf.whole(), d_pos_buf.whole(), d_params.whole())
    })
    .unwrap();
    let (base, signs) = deform::cpu::template_terms(&t).unwrap();
    let p = widen(&params);
    assert_close(
        "deformed positions",
        &read_f32(&gpu, &pos, 3 * v),
        &deform::cpu::forward(&base, &signs, &p),
        REL,
    );
    let twin = deform::cpu::backward(&base, &signs, &p, &widen(&d_pos));
    let gpu_d = read_f32(&gpu, &d_params, 3 * v + 3);
    assert_close("d displace", &gpu_d[..3 * v], &twin[..3 * v], REL);
    // The centre's gradient sums 3·162 terms of both signs: compared against its own scale.
    assert_close("d center", &gpu_d[3 * v..], &twin[3 * v..], REL);
}

#[test]
fn adam_matches_its_twin_over_three_steps() {
    let Some(gpu) = common::gpu() else { return };
    let mut rng = common::rng(6);
    // 250 texels of four and a tail of three (the two kernels).
    let n = 1003;
    // SoftRas's demo settings take ATen's other lerp branch (weight 1 − β1 = 0.5).
    for options in [
        AdamOptions::default(),
        AdamOptions {
            lr: 0.01,
            betas: (0.5, 0.99),
            eps: 1e-8,
        },
    ] {
        let params: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0f32)).collect();
        let grads: Vec<Vec<f32>> = (0..3)
            .map(|_| (0..n).map(|_| rng.random_range(-2.0..2.0f32)).collect())
            .collect();
        let adam = Adam::new(&gpu, n as u64, options).unwrap();
        let p_buf = gpu.upload_buffer("params", &params).unwrap();
        let g_bufs: Vec<Buffer> = grads
            .iter()
            .map(|g| gpu.upload_buffer("grads", g).unwrap())
            .collect();
        gpu.submit_and_wait(|rec| {
            for (t, g) in g_bufs.iter().enumerate() {
                adam.record_step(rec, p_buf.whole(), g.whole(), t as u32 + 1)?;
            }
            Ok(())
        })
        .unwrap();
        let (mut p, mut m, mut v) = (widen(&params), vec![0.0; n], vec![0.0; n]);
        for (t, g) in grads.iter().enumerate() {
            adam::cpu::step(&mut p, &widen(g), &mut m, &mut v, t as u32 + 1, &options);
        }
        let (gm, gv) = adam.moments();
        assert_close("Adam m", &read_f32(&gpu, gm, n), &m, REL);
        assert_close("Adam v", &read_f32(&gpu, gv, n), &v, REL);
        assert_close("Adam params", &read_f32(&gpu, &p_buf, n), &p, REL);
    }
}

/// Everything but the renderer, three iterations in one command buffer: deform → Laplacian
/// (written) + flatten (accumulated) → deform backward → Adam; plus both image losses.
struct Iteration {
    deform: Deform,
    reg: Regularizers,
    adam: Adam,
    iou: SilhouetteLoss,
    mse: ImageMse,
    initial: Buffer,
    params: Buffer,
    positions: Buffer,
    d_positions: Buffer,
    d_params: Buffer,
    images: Buffer,
    targets: Buffer,
    rgba_targets: Buffer,
    d_image: Buffer,
    pixels: usize,
}

const ITERATIONS: u32 = 3;
const OPTIONS: AdamOptions = AdamOptions {
    lr: 0.01,
    betas: (0.5, 0.99),
    eps: 1e-8,
};

impl Iteration {
    fn new(gpu: &Context, t: &[[f32; 3]], faces: &[[u32; 3]], initial: &[f32]) -> Self {
        let v = t.len() as u64;
        let mut rng = common::rng(8);
        let (views, w, h) = (2, 19, 21);
        let px = (views * w * h) as usize;
        let silhouettes: Vec<f32> = (0..px).map(|i| f32::from(i % 5 < 2)).collect();
        let device =
            |name: &str, bytes: u64| gpu.create_buffer(name, bytes, MemoryKind::Device).unwrap();
        Self {
            deform: Deform::new(gpu, t).unwrap(),
            reg: Regularizers::new(gpu, faces, t.len()).unwrap(),
            adam: Adam::new(gpu, 3 * v + 3, OPTIONS).unwrap(),
            iou: SilhouetteLoss::new(gpu, views, w, h).unwrap(),
            mse: ImageMse::new(gpu, views, w, h).unwrap(),
            initial: gpu.upload_buffer("initial params", initial).unwrap(),
            params: device("params", 4 * (3 * v + 3)),
            positions: device("positions", 12 * v),
            d_positions: device("d positions", 12 * v),
            d_params: device("d params", 4 * (3 * v + 3)),
            images: gpu
                .upload_buffer("images", &random_rgba(&mut rng, px))
                .unwrap(),
            targets: gpu.upload_buffer("silhouettes", &silhouettes).unwrap(),
            rgba_targets: gpu
                .upload_buffer("RGBA targets", &random_rgba(&mut rng, px))
                .unwrap(),
            d_image: device("d_image", 16 * px as u64),
            pixels: px,
        }
    }

    fn record(&self, rec: &mut softvk::gpu::Recorder<'_>) -> softvk::Result<()> {
        let bytes = 4 * self.deform.param_count();
        rec.copy(&self.initial, 0, &self.params, 0, bytes);
        self.adam.record_reset(rec);
        for step in 1..=ITERATIONS {
            let (params, positions) = (self.params.whole(), self.positions.whole());
            self.deform.record_forward(rec, params, positions)?;
            let d_pos = GradOut::write(self.d_positions.whole());
            self.reg
                .record_laplacian(rec, positions, Some(d_pos.weighted(0.03)))?;
            self.reg.record_flatten(
                rec,
                positions,
                Some(GradOut::accumulate(self.d_positions.whole(), 0.0003)),
            )?;
            self.deform.record_backward(
                rec,
                params,
                self.d_positions.whole(),
                self.d_params.whole(),
            )?;
            self.adam
                .record_step(rec, params, self.d_params.whole(), step)?;
        }
        let d_image = GradOut::write(self.d_image.whole());
        self.iou.record(
            rec,
            self.images.whole(),
            self.targets.whole(),
            Some(d_image),
        )?;
        self.mse.record(
            rec,
            self.images.whole(),
            self.rgba_targets.whole(),
            Some(GradOut::accumulate(self.d_image.whole(), 1.0)),
        )
    }

    /// Every output, as bits.
    fn snapshot(&self, gpu: &Context) -> Vec<u32> {
        let n = self.deform.param_count() as usize;
        let v = 3 * self.deform.vertex_count() as usize;
        let px = 4 * self.pixels;
        let (m, second) = self.adam.moments();
        let mut all: Vec<u32> = Vec::new();
        for (buffer, count) in [
            (&self.params, n),
            (&self.positions, v),
            (&self.d_positions, v),
            (&self.d_params, n),
            (m, n),
            (second, n),
            (&self.d_image, px),
            (self.reg.values_buffer(), 2),
            (self.iou.loss_buffer(), 1),
            (self.iou.stats_buffer(), 4 * 2),
            (self.mse.loss_buffer(), 1),
        ] {
            all.extend(gpu.read_buffer::<u32>(buffer, 0, count).unwrap());
        }
        all
    }
}

#[test]
fn a_whole_iteration_records_into_one_command_buffer_matches_the_twins_and_repeats_bit_identically()
{
    let Some(gpu) = common::gpu() else { return };
    let (t, faces) = template(2, 7);
    let v = t.len();
    let mut rng = common::rng(9);
    let initial: Vec<f32> = (0..3 * v + 3)
        .map(|_| rng.random_range(-0.3..0.3f32))
        .collect();
    let it = Iteration::new(&gpu, &t, &faces, &initial);
    let recorded = gpu.record(None, |rec| it.record(rec)).unwrap();
    recorded.submit_and_wait().unwrap();
    let first = it.snapshot(&gpu);

    // The twins, chained the same way.
    let (base, signs) = deform::cpu::template_terms(&t).unwrap();
    let (mut p, mut m, mut second) = (widen(&initial), vec![0.0; 3 * v + 3], vec![0.0; 3 * v + 3]);
    for step in 1..=ITERATIONS {
        let x = deform::cpu::forward(&base, &signs, &p);
        let (_, lap) = laplacian::cpu::loss_and_grad(it.reg.adjacency(), &x);
        let (_, flat) = flatten::cpu::loss_and_grad(it.reg.flatten_edges(), &x);
        let d_x: Vec<f64> = lap
            .iter()
            .zip(&flat)
            .map(|(l, f)| 0.03 * l + 0.0003 * f)
            .collect();
        let d_p = deform::cpu::backward(&base, &signs, &p, &d_x);
        adam::cpu::step(&mut p, &d_p, &mut m, &mut second, step, &OPTIONS);
    }
    assert_close(
        "params after 3 iterations",
        &read_f32(&gpu, &it.params, 3 * v + 3),
        &p,
        REL,
    );

    // The same command buffer again, from the same initial state: the same bits.
    recorded.submit_and_wait().unwrap();
    assert!(
        first == it.snapshot(&gpu),
        "a repeated run changed some bits"
    );
    // And a second recording of the same work.
    gpu.submit_and_wait(|rec| it.record(rec)).unwrap();
    assert!(
        first == it.snapshot(&gpu),
        "a re-recorded run changed some bits"
    );
}

fn expect_input<T>(what: &str, result: softvk::Result<T>) {
    match result {
        Err(Error::Input(message)) => eprintln!("{what}: {message}"),
        Err(other) => panic!("{what}: expected an input error, got {other}"),
        Ok(_) => panic!("{what}: expected an input error, got Ok"),
    }
}

#[test]
fn mismatched_sizes_and_bad_inputs_are_errors_not_panics() {
    let Some(gpu) = common::gpu() else { return };
    // Buffers are rounded up to the device's alignment: bind an exact 4-float range.
    let small_buffer = gpu.create_buffer("small", 16, MemoryKind::Device).unwrap();
    let small = small_buffer.range(0, 16);
    let big = gpu.create_buffer("big", 4096, MemoryKind::Device).unwrap();

    expect_input("no views", SilhouetteLoss::new(&gpu, 0, 4, 4).map(|_| ()));
    expect_input("empty image", ImageMse::new(&gpu, 1, 0, 4).map(|_| ()));
    match SilhouetteLoss::new(&gpu, 4, 1 << 14, 1 << 14) {
        Err(
            e @ Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                ..
            },
        ) => eprintln!("huge images: {e}"),
        Err(other) => panic!("huge images: expected a limit error, got {other}"),
        Ok(_) => panic!("huge images: expected a limit error"),
    }
    let iou = SilhouetteLoss::new(&gpu, 2, 8, 8).unwrap();
    expect_input(
        "short targets",
        gpu.submit_and_wait(|rec| iou.record(rec, big.whole(), small, None)),
    );
    let mse = ImageMse::new(&gpu, 1, 8, 8).unwrap();
    expect_input(
        "short d_image",
        gpu.submit_and_wait(|rec| {
            mse.record(rec, big.whole(), big.whole(), Some(GradOut::write(small)))
        }),
    );

    expect_input("no faces", Regularizers::new(&gpu, &[], 3).map(|_| ()));
    expect_input(
        "index out of range",
        Regularizers::new(&gpu, &[[0, 1, 7]], 3).map(|_| ()),
    );
    expect_input(
        "three faces on one edge",
        Regularizers::new(&gpu, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]], 5).map(|_| ()),
    );
    let (t, faces) = template(1, 1);
    let reg = Regularizers::new(&gpu, &faces, t.len()).unwrap();
    expect_input(
        "short positions",
        gpu.submit_and_wait(|rec| reg.record_laplacian(rec, small, None)),
    );
    expect_input(
        "short flatten gradient",
        gpu.submit_and_wait(|rec| {
            reg.record_flatten(rec, big.whole(), Some(GradOut::write(small)))
        }),
    );

    expect_input(
        "template on the cube's face",
        Deform::new(&gpu, &[[1.0, 0.5, 0.5]]).map(|_| ()),
    );
    let deform = Deform::new(&gpu, &t).unwrap();
    expect_input(
        "short params",
        gpu.submit_and_wait(|rec| deform.record_forward(rec, small, big.whole())),
    );

    let bad = AdamOptions {
        betas: (0.9, 1.5),
        ..AdamOptions::default()
    };
    expect_input("β2 > 1", Adam::new(&gpu, 4, bad).map(|_| ()));
    let adam = Adam::new(&gpu, 8, AdamOptions::default()).unwrap();
    expect_input(
        "step 0",
        gpu.submit_and_wait(|rec| adam.record_step(rec, big.whole(), big.whole(), 0)),
    );
    expect_input(
        "short grads",
        gpu.submit_and_wait(|rec| adam.record_step(rec, big.whole(), small, 1)),
    );
}
