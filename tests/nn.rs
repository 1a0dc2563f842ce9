//! Neural-network layers (`softvk::nn`): the f64 twins' gradients against central finite
//! differences, the GPU forward and backward against the twins, determinism, a small
//! conv→conv→linear→linear network with one Adam step, and the refusals.

mod common;

use softvk::fit::adam::{self, Adam, AdamOptions};
use softvk::gpu::{Buffer, Context};
use softvk::nn::{self, Activation, Conv2d, Layer, Linear, Sequential, cpu};
use softvk::{Error, LimitKind};
use softvk_testing::Lcg;

/// `n` values uniform in [-scale, scale) from `rng`.
fn uniform(rng: &mut Lcg, n: usize, scale: f64) -> Vec<f64> {
    (0..n).map(|_| scale * (2.0 * rng.unit() - 1.0)).collect()
}

const ACTIVATIONS: [Activation; 5] = [
    Activation::Identity,
    Activation::Relu,
    Activation::LeakyRelu(0.1),
    Activation::Sigmoid,
    Activation::Tanh,
];

/// (in_h, in_w, kernel, stride, padding): kernels 3, 4, 5; strides 1, 2; paddings 0, 1, 2; odd
/// sizes whose output is floored ((7 + 0 − 4) / 2 = 1.5, (9 + 2 − 5) / 2 = 3, (6 + 4 − 5) / 2 = 2.5);
/// rows wide enough for several of the kernels' 4-column blocks, with a partial last one.
/// (in_h, in_w, kernel, stride, padding), counted from 1 below. Input rows of a multiple of 4
/// columns (8 to 13)
/// take the texel forward (`nn_conv_forward4`), its window starting 0, 2, 3, 3, 2 and 0 columns
/// into a texel; output rows of a multiple of 4 (10 to 15) the texel input gradient
/// (`nn_conv_dinput4`; 14 and 15 with input rows of 9 and 10 columns, strides 2 and 3); both
/// (10 to 13) the texel weight gradient (`nn_conv_wgrad4`); the others the scalar kernels. The
/// last two pad by as much as their kernel or more (all texel kernels, then the texel input
/// gradient only).
const CONV_SHAPES: [(u32, u32, u32, u32, u32); 17] = [
    (5, 6, 3, 1, 0),
    (7, 6, 4, 2, 0),
    (6, 7, 4, 2, 1),
    (9, 7, 5, 2, 1),
    (6, 5, 5, 2, 2),
    (4, 13, 3, 1, 1),
    (5, 19, 5, 2, 2),
    (5, 8, 3, 1, 0),
    (7, 12, 5, 2, 2),
    (6, 16, 4, 2, 1),
    (9, 8, 3, 1, 1),
    (5, 16, 5, 2, 2),
    (5, 8, 5, 1, 0),
    (4, 9, 2, 2, 0),
    (6, 10, 3, 3, 1),
    (4, 4, 2, 2, 2),
    (3, 2, 1, 1, 1),
];

fn conv(shape: (u32, u32, u32, u32, u32), in_c: u32, out_c: u32, act: Activation) -> Conv2d {
    let (in_h, in_w, kernel, stride, padding) = shape;
    Conv2d {
        in_channels: in_c,
        out_channels: out_c,
        kernel,
        stride,
        padding,
        in_h,
        in_w,
        activation: act,
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Every component of `got` within `rel` of its reference plus `floor` times the largest
/// reference of its own part: `starts` cuts `want` into parts (each layer's parameters), so a
/// layer whose gradients are small is held to its own size, not to its neighbour's.
fn held(what: &str, got: &[f64], want: &[f64], starts: &[usize], rel: f64, floor: f64) {
    assert_eq!(got.len(), want.len());
    let mut ends: Vec<usize> = starts.iter().skip(1).copied().collect();
    ends.push(want.len());
    let (mut worst, mut at) = (0.0f64, 0);
    for (&start, &end) in starts.iter().zip(&ends) {
        let part = &want[start..end];
        let size = part.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if size == 0.0 {
            assert!(
                got[start..end].iter().all(|&g| g == 0.0),
                "{what}: part at {start} is not zero"
            );
            continue;
        }
        let (near, relative) = common::measured(&got[start..end], part, 1e-2 * size);
        eprintln!(
            "{what} [{start}..{end}]: near zero {:.2e} of the part's largest, relative {relative:.2e}",
            near / size
        );
        let (share, i) = common::worst_share(&got[start..end], part, rel, floor * size);
        if share > worst || share.is_nan() {
            (worst, at) = (share, start + i);
        }
    }
    eprintln!("{what}: worst component uses {worst:.3} of its bound");
    assert!(
        worst <= 1.0,
        "{what}: component {at} is {} against {} (bound {rel:e} of itself + {floor:e} of its part's largest)",
        got[at],
        want[at]
    );
}

/// The twin against central differences (h = 1e-6 in f64): each component within FD_REL of
/// itself plus FD_FLOOR of its part's largest, about 3 times the worst measured over every
/// layer shape (9.8e-8 relative, 2.7e-9 of the largest near zero: the differences' own error).
const FD_REL: f64 = 3e-7;
const FD_FLOOR: f64 = 8e-9;
/// The kernels (f32) against the twin: each component within GPU_REL of itself plus GPU_FLOOR of
/// its part's largest (a layer's parameters, an output, an input), about 3 times the worst
/// measured on lavapipe (7.9e-8 of the part's largest near zero, where the batch's f32 sums
/// cancel; relative errors of the larger components below 1e-6).
const GPU_REL: f64 = 3e-6;
const GPU_FLOOR: f64 = 2.4e-7;

/// Checks the twin's gradient of L = Σ r · layer(x) against central differences, every
/// parameter and every input.
fn check_layer_gradient(layer: &Layer, batch: usize, seed: u64) {
    let mut rng = Lcg(seed);
    let params = uniform(&mut rng, layer.param_count() as usize, 0.5);
    let input = uniform(&mut rng, batch * layer.input_len() as usize, 1.0);
    let r = uniform(&mut rng, batch * layer.output_len() as usize, 1.0);
    let output = cpu::layer_forward(layer, &params, &input, batch);
    let g = cpu::layer_backward(layer, &params, &input, &output, &r, batch);
    let loss = |p: &[f64], x: &[f64]| dot(&r, &cpu::layer_forward(layer, p, x, batch));
    let h = 1e-6;
    let mut fd_params = vec![0.0; params.len()];
    for (j, fd) in fd_params.iter_mut().enumerate() {
        let (mut hi, mut lo) = (params.clone(), params.clone());
        hi[j] += h;
        lo[j] -= h;
        *fd = (loss(&hi, &input) - loss(&lo, &input)) / (2.0 * h);
    }
    let mut fd_input = vec![0.0; input.len()];
    for (i, fd) in fd_input.iter_mut().enumerate() {
        let (mut hi, mut lo) = (input.clone(), input.clone());
        hi[i] += h;
        lo[i] -= h;
        *fd = (loss(&params, &hi) - loss(&params, &lo)) / (2.0 * h);
    }
    held(
        &format!("{layer:?} d_params"),
        &g.d_params,
        &fd_params,
        &[0],
        FD_REL,
        FD_FLOOR,
    );
    held(
        &format!("{layer:?} d_input"),
        &g.d_input,
        &fd_input,
        &[0],
        FD_REL,
        FD_FLOOR,
    );
    // Not vacuous: the gradients are not all zero.
    assert!(g.d_params.iter().any(|&v| v.abs() > 1e-3), "{layer:?}");
    assert!(g.d_input.iter().any(|&v| v.abs() > 1e-3), "{layer:?}");
}

#[test]
fn conv_twin_gradients_match_finite_differences_for_every_activation_and_shape() {
    for (a, act) in ACTIVATIONS.into_iter().enumerate() {
        for (s, shape) in CONV_SHAPES.into_iter().enumerate() {
            let layer = Layer::Conv2d(conv(shape, 2, 3, act));
            check_layer_gradient(&layer, 2, (10 * a + s) as u64);
        }
    }
}

#[test]
fn linear_twin_gradients_match_finite_differences_for_every_activation() {
    for (a, act) in ACTIVATIONS.into_iter().enumerate() {
        let layer = Layer::Linear(Linear {
            in_features: 7,
            out_features: 5,
            activation: act,
        });
        check_layer_gradient(&layer, 3, 100 + a as u64);
    }
}

#[test]
fn conv_twin_matches_a_hand_computed_strided_padded_convolution() {
    // One 3×3 input 1..9, one 2×2 kernel [[1, 2], [3, 4]], bias 0.5, stride 2, padding 1:
    // out 2×2; out[0][0] sees only in[0][0] (tap (1, 1)): 4·1 + 0.5.
    let c = Conv2d {
        in_channels: 1,
        out_channels: 1,
        kernel: 2,
        stride: 2,
        padding: 1,
        in_h: 3,
        in_w: 3,
        activation: Activation::Identity,
    };
    let input: Vec<f64> = (1..=9).map(f64::from).collect();
    let out = cpu::conv2d_forward(&c, &[1.0, 2.0, 3.0, 4.0, 0.5], &input, 1);
    // [0][1]: taps (1,0),(1,1) on in[0][1], in[0][2]: 3·2 + 4·3; [1][0]: taps (0,1),(1,1) on
    // in[1][0], in[2][0]: 2·4 + 4·7; [1][1]: all four on in[1..3][1..3]: 5 + 12 + 24 + 36.
    assert_eq!(out, vec![4.5, 18.5, 36.5, 77.5]);
}

fn upload(ctx: &Context, name: &str, data: &[f64]) -> Buffer {
    let data: Vec<f32> = data.iter().map(|&v| v as f32).collect();
    ctx.upload_buffer(name, &data).unwrap()
}

fn read(ctx: &Context, buffer: &Buffer, n: usize) -> Vec<f64> {
    ctx.read_buffer::<f32>(buffer, 0, n)
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect()
}

fn f32s(v: &[f64]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x as f32)).collect()
}

/// A network's GPU buffers for one batch, with the twin's results for the same f32 data.
struct Run {
    params: Buffer,
    input: Buffer,
    d_output: Buffer,
    d_params: Buffer,
    d_input: Buffer,
}

impl Run {
    fn new(
        ctx: &Context,
        net: &Sequential,
        batch: usize,
        seed: u64,
    ) -> (Run, Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut rng = Lcg(seed);
        let params: Vec<f64> = net.init(seed).iter().map(|&p| f64::from(p)).collect();
        let input = f32s(&uniform(&mut rng, batch * net.input_len() as usize, 1.0));
        let d_output = f32s(&uniform(&mut rng, batch * net.output_len() as usize, 1.0));
        // Garbage where the gradients go: the backward must overwrite it.
        let garbage = vec![7.0; net.param_count() as usize];
        let run = Run {
            params: upload(ctx, "test params", &params),
            input: upload(ctx, "test input", &input),
            d_output: upload(ctx, "test d_output", &d_output),
            d_params: upload(ctx, "test d_params", &garbage),
            d_input: upload(ctx, "test d_input", &vec![7.0; input.len()]),
        };
        (run, params, input, d_output)
    }

    fn record(&self, ctx: &Context, net: &Sequential, batch: u32, with_d_input: bool) {
        ctx.submit_and_wait(|rec| {
            net.record_forward(rec, self.params.whole(), self.input.whole(), batch)?;
            net.record_backward(
                rec,
                self.params.whole(),
                self.input.whole(),
                self.d_output.whole(),
                self.d_params.whole(),
                with_d_input.then(|| self.d_input.whole()),
                batch,
            )
        })
        .unwrap();
    }
}

/// Runs `layers` forward and backward on the GPU at `batch` and compares every layer's output,
/// d_params and (when asked) d_input with the twin, then checks that a rerun is bit-identical.
fn check_network(ctx: &Context, layers: &[Layer], batch: usize, seed: u64, with_d_input: bool) {
    let net = Sequential::new(ctx, layers, batch as u32).unwrap();
    let (run, params, input, d_output) = Run::new(ctx, &net, batch, seed);
    run.record(ctx, &net, batch as u32, with_d_input);

    let outputs = cpu::sequential_forward(layers, &params, &input, batch);
    for (l, want) in outputs.iter().enumerate() {
        let got = read(ctx, net.layer_output(l).unwrap(), want.len());
        held(
            &format!("{layers:?}: layer {l}'s output"),
            &got,
            want,
            &[0],
            GPU_REL,
            GPU_FLOOR,
        );
    }
    let want = cpu::sequential_backward(layers, &params, &input, &outputs, &d_output, batch);
    let got = read(ctx, &run.d_params, want.d_params.len());
    let starts: Vec<usize> = net.param_offsets().iter().map(|&o| o as usize).collect();
    held(
        &format!("{layers:?}: d_params"),
        &got,
        &want.d_params,
        &starts,
        GPU_REL,
        GPU_FLOOR,
    );
    let got_input = read(ctx, &run.d_input, want.d_input.len());
    if with_d_input {
        held(
            &format!("{layers:?}: d_input"),
            &got_input,
            &want.d_input,
            &[0],
            GPU_REL,
            GPU_FLOOR,
        );
    } else {
        assert!(
            got_input.iter().all(|&v| v == 7.0),
            "d_input written unasked"
        );
    }

    // A rerun is bit-identical.
    let bits = |b: &Buffer, n: usize| ctx.read_buffer::<u32>(b, 0, n).unwrap();
    let out_len = batch * net.output_len() as usize;
    let first = (
        bits(net.output(), out_len),
        bits(&run.d_params, got.len()),
        bits(&run.d_input, got_input.len()),
    );
    run.record(ctx, &net, batch as u32, with_d_input);
    let second = (
        bits(net.output(), out_len),
        bits(&run.d_params, got.len()),
        bits(&run.d_input, got_input.len()),
    );
    assert!(first == second, "{layers:?}: a rerun differs");
}

#[test]
fn gpu_conv_forward_and_backward_match_the_twin_for_every_activation_and_shape() {
    let Some(ctx) = common::gpu() else { return };
    for (a, act) in ACTIVATIONS.into_iter().enumerate() {
        for (s, shape) in CONV_SHAPES.into_iter().enumerate() {
            // Every activation on every shape would build 25 networks; a diagonal covers both.
            if (a + s) % 2 == 1 && a != 0 {
                continue;
            }
            // 3 and 5 channels: the kernels' 4-channel blocks, one partial.
            let layer = Layer::Conv2d(conv(shape, 3, 5, act));
            check_network(&ctx, &[layer], 2, (10 * a + s) as u64, true);
        }
    }
}

/// Rows of 37 inputs take the scalar kernels; rows of 36 (whole texels, the weights at a texel
/// boundary) the texel ones; in the chain, the third layer's rows are whole texels but its
/// weights start at float (5 · 3 + 3) + (3 · 8 + 8) = 50, off a texel boundary, so it takes the
/// scalar ones.
#[test]
fn gpu_linear_forward_and_backward_match_the_twin_for_every_activation() {
    let Some(ctx) = common::gpu() else { return };
    let linear = |i, o, activation| {
        Layer::Linear(Linear {
            in_features: i,
            out_features: o,
            activation,
        })
    };
    for (a, act) in ACTIVATIONS.into_iter().enumerate() {
        for in_features in [37, 36] {
            let layer = linear(in_features, 19, act);
            check_network(&ctx, &[layer], 5, 200 + a as u64, true);
        }
        let chain = [linear(5, 3, act), linear(3, 8, act), linear(8, 5, act)];
        check_network(&ctx, &chain, 5, 300 + a as u64, true);
    }
}

fn small_network() -> Vec<Layer> {
    let c1 = conv((9, 8, 3, 2, 1), 2, 4, Activation::LeakyRelu(0.2));
    let c2 = conv((c1.out_h(), c1.out_w(), 3, 1, 1), 4, 3, Activation::Relu);
    vec![
        c1.into(),
        c2.into(),
        Linear {
            in_features: 3 * c2.out_h() * c2.out_w(),
            out_features: 10,
            activation: Activation::Tanh,
        }
        .into(),
        Linear {
            in_features: 10,
            out_features: 6,
            activation: Activation::Identity,
        }
        .into(),
    ]
}

#[test]
fn gpu_conv_conv_linear_linear_network_matches_its_twin_and_one_adam_step() {
    let Some(ctx) = common::gpu() else { return };
    let layers = small_network();
    let batch = 3;
    // Without d_input, as a network's first layer needs none.
    check_network(&ctx, &layers, batch, 5, false);

    let net = Sequential::new(&ctx, &layers, batch as u32).unwrap();
    let (run, mut params, input, d_output) = Run::new(&ctx, &net, batch, 9);
    let options = AdamOptions {
        lr: 0.01,
        ..AdamOptions::default()
    };
    let adam = Adam::new(&ctx, net.param_count(), options).unwrap();
    ctx.submit_and_wait(|rec| {
        net.record_forward(rec, run.params.whole(), run.input.whole(), batch as u32)?;
        net.record_backward(
            rec,
            run.params.whole(),
            run.input.whole(),
            run.d_output.whole(),
            run.d_params.whole(),
            None,
            batch as u32,
        )?;
        adam.record_step(rec, run.params.whole(), run.d_params.whole(), 1)
    })
    .unwrap();
    let outputs = cpu::sequential_forward(&layers, &params, &input, batch);
    let g = cpu::sequential_backward(&layers, &params, &input, &outputs, &d_output, batch);
    let before = params.clone();
    let n = params.len();
    let (mut m, mut v) = (vec![0.0; n], vec![0.0; n]);
    adam::cpu::step(&mut params, &g.d_params, &mut m, &mut v, 1, &options);
    let got = read(&ctx, &run.params, n);
    let mut moved = 0;
    for j in 0..n {
        assert!(
            (got[j] - params[j]).abs() <= 0.02 * options.lr,
            "parameter {j}: GPU {} vs twin {} (from {})",
            got[j],
            params[j],
            before[j]
        );
        moved += usize::from((got[j] - before[j]).abs() > 0.5 * options.lr);
    }
    // Adam's first step moves every parameter with a clear gradient by about lr.
    assert!(moved > n / 2, "only {moved} of {n} parameters moved");
}

#[test]
fn wrong_sizes_and_batches_are_refused_with_clear_errors() {
    let Some(ctx) = common::gpu() else { return };
    let layers = small_network();
    let net = Sequential::new(&ctx, &layers, 2).unwrap();
    let (run, ..) = Run::new(&ctx, &net, 2, 1);
    let p = 4 * net.param_count();
    let x = 4 * 2 * net.input_len();
    let y = 4 * 2 * net.output_len();
    let forward = |params, input, batch| {
        ctx.submit_and_wait(|rec| net.record_forward(rec, params, input, batch))
    };
    let small = |e: Result<(), Error>| matches!(e, Err(Error::BufferTooSmall { .. }));
    assert!(small(forward(
        run.params.range(0, p - 4),
        run.input.whole(),
        2
    )));
    assert!(small(forward(
        run.params.whole(),
        run.input.range(0, x - 4),
        2
    )));
    assert!(matches!(
        forward(run.params.whole(), run.input.whole(), 3),
        Err(Error::Input(_))
    ));
    let backward = |d_output, d_params, d_input| {
        ctx.submit_and_wait(|rec| {
            net.record_backward(
                rec,
                run.params.whole(),
                run.input.whole(),
                d_output,
                d_params,
                d_input,
                2,
            )
        })
    };
    assert!(small(backward(
        run.d_output.range(0, y - 4),
        run.d_params.whole(),
        None
    )));
    assert!(small(backward(
        run.d_output.whole(),
        run.d_params.range(0, p - 4),
        None
    )));
    assert!(small(backward(
        run.d_output.whole(),
        run.d_params.whole(),
        Some(run.d_input.range(0, x - 4))
    )));
    assert!(
        backward(
            run.d_output.whole(),
            run.d_params.whole(),
            Some(run.d_input.whole())
        )
        .is_ok()
    );

    // Sizes that do not chain.
    let mut broken = layers.clone();
    broken.swap(2, 3);
    assert!(matches!(
        Sequential::new(&ctx, &broken, 2),
        Err(Error::Input(_))
    ));
}

#[test]
fn loops_over_the_devices_cap_are_refused_as_device_limits() {
    let Some(ctx) = common::gpu() else { return };
    let wide = Layer::Linear(Linear {
        in_features: 70_000,
        out_features: 1,
        activation: Activation::Relu,
    });
    let narrow = Layer::Linear(Linear {
        in_features: 4,
        out_features: 2,
        activation: Activation::Relu,
    });
    // A forward over 70 000 inputs; a parameter gradient summed over 40 000 samples.
    assert!(wide.loop_iterations(1) > 65_535);
    assert!(narrow.loop_iterations(40_000) > 65_535);
    assert!(narrow.loop_iterations(1_000) < 65_535);
    match ctx.info().shader_loop_limit() {
        Some(limit) => {
            for (layer, capacity) in [(wide, 1), (narrow, 40_000)] {
                match Sequential::new(&ctx, &[layer], capacity) {
                    Err(Error::DeviceLimit {
                        kind: LimitKind::LoopIterations,
                        need,
                        max,
                        ..
                    }) => assert!(need > max && max == limit),
                    Err(e) => panic!("{layer:?} at {capacity}: wrong error {e}"),
                    Ok(_) => panic!("{layer:?} at {capacity}: accepted"),
                }
            }
            assert!(Sequential::new(&ctx, &[narrow], 1_000).is_ok());
        }
        None => eprintln!("{} caps no loops: nothing to refuse", ctx.info().name),
    }
}

#[test]
fn init_draws_pytorchs_bounds_layer_by_layer() {
    let layers = small_network();
    let params = nn::init(&layers, 3);
    let (offsets, total) = nn::param_offsets(&layers);
    assert_eq!(params.len() as u64, total);
    for (layer, &at) in layers.iter().zip(&offsets) {
        let bound = 1.0 / (layer.fan_in() as f32).sqrt();
        let slice = &params[at as usize..(at + layer.param_count()) as usize];
        let max = slice.iter().fold(0f32, |m, w| m.max(w.abs()));
        assert!(
            max <= bound && max > 0.7 * bound,
            "{layer:?}: max {max}, bound {bound}"
        );
    }
}
