//! f64 CPU twins of the layer kernels, loop for loop like the shaders (the same sums in the same
//! orders): the oracle the GPU is tested against, and checked themselves by finite differences.
//!
//! Every function takes a layer's own parameter slice (weights, then bias) and batch-major
//! tensors of `batch` samples.

use super::{Activation, Conv2d, Layer, Linear, param_offsets};

/// The activation of `x` (`activate` in `nn.glsl`).
pub fn activate(a: Activation, x: f64) -> f64 {
    match a {
        Activation::Identity => x,
        Activation::Relu => x.max(0.0),
        Activation::LeakyRelu(slope) => {
            if x > 0.0 {
                x
            } else {
                f64::from(slope) * x
            }
        }
        Activation::Sigmoid => 1.0 / (1.0 + (-x).exp()),
        Activation::Tanh => x.tanh(),
    }
}

/// The activation's derivative where its output is `y` (`derivative_from_output` in `nn.glsl`).
pub fn derivative_from_output(a: Activation, y: f64) -> f64 {
    match a {
        Activation::Identity => 1.0,
        Activation::Relu => {
            if y > 0.0 {
                1.0
            } else {
                0.0
            }
        }
        Activation::LeakyRelu(slope) => {
            if y > 0.0 {
                1.0
            } else {
                f64::from(slope)
            }
        }
        Activation::Sigmoid => y * (1.0 - y),
        Activation::Tanh => 1.0 - y * y,
    }
}

/// A layer's gradients: with respect to its input (`batch × input_len`) and to its parameters
/// (weights, then bias).
#[derive(Clone, Debug, PartialEq)]
pub struct LayerGrads {
    /// dL/d(input), batch-major like the input.
    pub d_input: Vec<f64>,
    /// dL/d(parameters), in the parameters' order.
    pub d_params: Vec<f64>,
}

/// The taps `k` in `0..kernel` of output position `o` that land inside `0..side`
/// (`o·stride + k − padding`), as a range.
fn taps(c: &Conv2d, o: usize, side: usize) -> (usize, usize) {
    let origin = (o * c.stride as usize) as i64 - i64::from(c.padding);
    let k = i64::from(c.kernel);
    let lo = (-origin).max(0);
    let hi = (side as i64 - origin).clamp(0, k);
    (lo as usize, hi.max(lo) as usize)
}

/// `nn_conv_forward.comp`: `batch × O × out_h × out_w` activated outputs.
pub fn conv2d_forward(c: &Conv2d, params: &[f64], input: &[f64], batch: usize) -> Vec<f64> {
    let (ci, co, k) = (
        c.in_channels as usize,
        c.out_channels as usize,
        c.kernel as usize,
    );
    let (ih, iw, oh, ow) = (
        c.in_h as usize,
        c.in_w as usize,
        c.out_h() as usize,
        c.out_w() as usize,
    );
    let s = c.stride as usize;
    let p = c.padding as usize;
    let bias = &params[co * ci * k * k..];
    let mut out = vec![0.0; batch * co * oh * ow];
    for b in 0..batch {
        for o in 0..co {
            for oy in 0..oh {
                let (ky0, ky1) = taps(c, oy, ih);
                for ox in 0..ow {
                    let (kx0, kx1) = taps(c, ox, iw);
                    let mut acc = bias[o];
                    for ch in 0..ci {
                        let w = &params[(o * ci + ch) * k * k..];
                        let plane = &input[(b * ci + ch) * ih * iw..];
                        for ky in ky0..ky1 {
                            let iy = oy * s + ky - p;
                            for kx in kx0..kx1 {
                                acc += w[ky * k + kx] * plane[iy * iw + ox * s + kx - p];
                            }
                        }
                    }
                    out[((b * co + o) * oh + oy) * ow + ox] = activate(c.activation, acc);
                }
            }
        }
    }
    out
}

/// dL/d(pre-activation) from the output and dL/d(output) (`nn_act_backward.comp`).
fn through_activation(a: Activation, output: &[f64], d_output: &[f64]) -> Vec<f64> {
    output
        .iter()
        .zip(d_output)
        .map(|(&y, &g)| g * derivative_from_output(a, y))
        .collect()
}

/// `nn_act_backward`, `nn_conv_dinput`, `nn_conv_wgrad` and `nn_sum_rows`: the gradients from
/// the layer's input, its output and dL/d(output).
pub fn conv2d_backward(
    c: &Conv2d,
    params: &[f64],
    input: &[f64],
    output: &[f64],
    d_output: &[f64],
    batch: usize,
) -> LayerGrads {
    let (ci, co, k) = (
        c.in_channels as usize,
        c.out_channels as usize,
        c.kernel as usize,
    );
    let (ih, iw, oh, ow) = (
        c.in_h as usize,
        c.in_w as usize,
        c.out_h() as usize,
        c.out_w() as usize,
    );
    let (s, p) = (c.stride as usize, c.padding as usize);
    let d_pre = through_activation(c.activation, output, d_output);

    // Gathered: each input element sums over the outputs its taps reach, in the order o, ky, kx.
    let mut d_input = vec![0.0; batch * ci * ih * iw];
    for b in 0..batch {
        for ch in 0..ci {
            for iy in 0..ih {
                for ix in 0..iw {
                    let mut acc = 0.0;
                    for o in 0..co {
                        let w = &params[(o * ci + ch) * k * k..];
                        let d = &d_pre[(b * co + o) * oh * ow..];
                        for ky in 0..k {
                            let ny = iy + p;
                            if ny < ky || (ny - ky) % s != 0 || (ny - ky) / s >= oh {
                                continue;
                            }
                            for kx in 0..k {
                                let nx = ix + p;
                                if nx < kx || (nx - kx) % s != 0 || (nx - kx) / s >= ow {
                                    continue;
                                }
                                acc += w[ky * k + kx] * d[(ny - ky) / s * ow + (nx - kx) / s];
                            }
                        }
                    }
                    d_input[((b * ci + ch) * ih + iy) * iw + ix] = acc;
                }
            }
        }
    }

    // Per sample over its outputs (oy, ox), then over the batch in order.
    let weights = co * ci * k * k;
    let mut d_params = vec![0.0; weights + co];
    for b in 0..batch {
        for (j, dp) in d_params.iter_mut().enumerate() {
            let mut acc = 0.0;
            if j >= weights {
                let d = &d_pre[(b * co + j - weights) * oh * ow..];
                for &g in &d[..oh * ow] {
                    acc += g;
                }
            } else {
                let (kx, ky) = (j % k, (j / k) % k);
                let (ch, o) = ((j / (k * k)) % ci, j / (k * k * ci));
                let d = &d_pre[(b * co + o) * oh * ow..];
                let plane = &input[(b * ci + ch) * ih * iw..];
                for oy in 0..oh {
                    let Some(iy) = (oy * s + ky).checked_sub(p).filter(|&iy| iy < ih) else {
                        continue;
                    };
                    for ox in 0..ow {
                        let Some(ix) = (ox * s + kx).checked_sub(p).filter(|&ix| ix < iw) else {
                            continue;
                        };
                        acc += d[oy * ow + ox] * plane[iy * iw + ix];
                    }
                }
            }
            *dp += acc;
        }
    }
    LayerGrads { d_input, d_params }
}

/// `nn_linear_forward.comp`: `batch × O` activated outputs.
pub fn linear_forward(l: &Linear, params: &[f64], input: &[f64], batch: usize) -> Vec<f64> {
    let (ni, no) = (l.in_features as usize, l.out_features as usize);
    let mut out = vec![0.0; batch * no];
    for b in 0..batch {
        for o in 0..no {
            let mut acc = params[no * ni + o];
            for i in 0..ni {
                acc += params[o * ni + i] * input[b * ni + i];
            }
            out[b * no + o] = activate(l.activation, acc);
        }
    }
    out
}

/// `nn_act_backward`, `nn_linear_dinput` and `nn_linear_wgrad`: the gradients from the layer's
/// input, its output and dL/d(output).
pub fn linear_backward(
    l: &Linear,
    params: &[f64],
    input: &[f64],
    output: &[f64],
    d_output: &[f64],
    batch: usize,
) -> LayerGrads {
    let (ni, no) = (l.in_features as usize, l.out_features as usize);
    let d_pre = through_activation(l.activation, output, d_output);
    let mut d_input = vec![0.0; batch * ni];
    for b in 0..batch {
        for i in 0..ni {
            let mut acc = 0.0;
            for o in 0..no {
                acc += params[o * ni + i] * d_pre[b * no + o];
            }
            d_input[b * ni + i] = acc;
        }
    }
    let mut d_params = vec![0.0; no * ni + no];
    for (j, dp) in d_params.iter_mut().enumerate() {
        let mut acc = 0.0;
        if j >= no * ni {
            for b in 0..batch {
                acc += d_pre[b * no + j - no * ni];
            }
        } else {
            let (o, i) = (j / ni, j % ni);
            for b in 0..batch {
                acc += d_pre[b * no + o] * input[b * ni + i];
            }
        }
        *dp = acc;
    }
    LayerGrads { d_input, d_params }
}

/// One layer's forward ([`conv2d_forward`] or [`linear_forward`]).
pub fn layer_forward(layer: &Layer, params: &[f64], input: &[f64], batch: usize) -> Vec<f64> {
    match layer {
        Layer::Conv2d(c) => conv2d_forward(c, params, input, batch),
        Layer::Linear(l) => linear_forward(l, params, input, batch),
    }
}

/// One layer's backward ([`conv2d_backward`] or [`linear_backward`]).
pub fn layer_backward(
    layer: &Layer,
    params: &[f64],
    input: &[f64],
    output: &[f64],
    d_output: &[f64],
    batch: usize,
) -> LayerGrads {
    match layer {
        Layer::Conv2d(c) => conv2d_backward(c, params, input, output, d_output, batch),
        Layer::Linear(l) => linear_backward(l, params, input, output, d_output, batch),
    }
}

/// The twin of [`super::Sequential::record_forward`]: every layer's output, in order, from the
/// network's flat parameters.
pub fn sequential_forward(
    layers: &[Layer],
    params: &[f64],
    input: &[f64],
    batch: usize,
) -> Vec<Vec<f64>> {
    let (offsets, _) = param_offsets(layers);
    let mut outputs: Vec<Vec<f64>> = Vec::with_capacity(layers.len());
    for (layer, &offset) in layers.iter().zip(&offsets) {
        let x = outputs.last().map_or(input, Vec::as_slice);
        let y = layer_forward(layer, &params[offset as usize..], x, batch);
        outputs.push(y);
    }
    outputs
}

/// The twin of [`super::Sequential::record_backward`]: from the input, every layer's output
/// ([`sequential_forward`]) and dL/d(final output), the network's d_input and its flat d_params.
pub fn sequential_backward(
    layers: &[Layer],
    params: &[f64],
    input: &[f64],
    outputs: &[Vec<f64>],
    d_output: &[f64],
    batch: usize,
) -> LayerGrads {
    let (offsets, total) = param_offsets(layers);
    let mut d_params = vec![0.0; total as usize];
    let mut d = d_output.to_vec();
    for (l, layer) in layers.iter().enumerate().rev() {
        let x = if l == 0 { input } else { &outputs[l - 1] };
        let at = offsets[l] as usize;
        let g = layer_backward(layer, &params[at..], x, &outputs[l], &d, batch);
        d_params[at..at + g.d_params.len()].copy_from_slice(&g.d_params);
        d = g.d_input;
    }
    LayerGrads {
        d_input: d,
        d_params,
    }
}
