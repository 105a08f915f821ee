//! The network (docs/pillars.md): the pillar feature net, the 2D backbone and the head, with
//! batch norm already folded into each layer. Convolutions are im2col products through
//! nalgebra's gemm (matrixmultiply's packed kernels, picked for the CPU at run time).

use super::grid::{Pillars, GRID, POINT_FEATURES};
use super::weights::Weights;
use crate::PipelineError;
use nalgebra::{DMatrixView, DMatrixViewMut};

pub const PILLAR_CHANNELS: usize = 32;
pub const HEAD_CHANNELS: usize = 12;
/// The head's cells along each side (the pillar grid at stride 2).
pub const HEAD_GRID: usize = GRID / 2;

/// A channel-first feature map.
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    pub channels: usize,
    pub rows: usize,
    pub cols: usize,
    pub values: Vec<f32>,
}

impl Map {
    fn zeros(channels: usize, rows: usize, cols: usize) -> Self {
        Self { channels, rows, cols, values: vec![0.0; channels * rows * cols] }
    }

    pub fn at(&self, c: usize, r: usize, col: usize) -> f32 {
        self.values.get((c * self.rows + r) * self.cols + col).copied().unwrap_or(0.0)
    }
}

/// `out[m x n] = a[m x k] * b[k x n]`, all row-major.
fn matmul(a: &[f32], b: &[f32], out: &mut [f32], m: usize, k: usize, n: usize) {
    // A row-major [m x k] buffer is the column-major [k x m] matrix: compute out^T = b^T a^T.
    let a_t = DMatrixView::from_slice(a, k, m);
    let b_t = DMatrixView::from_slice(b, n, k);
    let mut out_t = DMatrixViewMut::from_slice(out, n, m);
    out_t.gemm(1.0, &b_t, &a_t, 0.0);
}

/// A layer's weight (in PyTorch's layout) and bias.
#[derive(Clone, Debug)]
struct Layer {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Layer {
    fn load(w: &Weights, name: &str, weight_dims: &[usize], outputs: usize) -> Result<Self, PipelineError> {
        Ok(Self {
            weight: w.get(&format!("{name}.weight"), weight_dims)?.to_vec(),
            bias: w.get(&format!("{name}.bias"), &[outputs])?.to_vec(),
        })
    }
}

/// A convolution with a square kernel and `pad = kernel / 2`, ReLU after it or not.
#[derive(Clone, Debug)]
struct Conv {
    layer: Layer,
    inputs: usize,
    outputs: usize,
    kernel: usize,
    stride: usize,
    relu: bool,
}

impl Conv {
    fn load(
        w: &Weights,
        name: &str,
        io: (usize, usize),
        kernel: usize,
        stride: usize,
        relu: bool,
    ) -> Result<Self, PipelineError> {
        let layer = Layer::load(w, name, &[io.1, io.0, kernel, kernel], io.1)?;
        Ok(Self { layer, inputs: io.0, outputs: io.1, kernel, stride, relu })
    }

    fn forward(&self, x: &Map, cols: &mut Vec<f32>) -> Map {
        let pad = self.kernel / 2;
        let rows = (x.rows + 2 * pad - self.kernel) / self.stride + 1;
        let width = (x.cols + 2 * pad - self.kernel) / self.stride + 1;
        let n = rows * width;
        let k = self.inputs * self.kernel * self.kernel;
        // im2col: one row per (input channel, kernel row, kernel column), one column per output pixel.
        cols.clear();
        cols.resize(k * n, 0.0);
        for (row_index, col_row) in cols.chunks_exact_mut(n).enumerate() {
            let (c, kr, kc) = (
                row_index / (self.kernel * self.kernel),
                row_index / self.kernel % self.kernel,
                row_index % self.kernel,
            );
            for r in 0..rows {
                let Some(src_r) = (r * self.stride + kr).checked_sub(pad).filter(|&v| v < x.rows) else { continue };
                let src_row = &x.values[(c * x.rows + src_r) * x.cols..][..x.cols];
                for (col, out) in col_row[r * width..][..width].iter_mut().enumerate() {
                    if let Some(v) = (col * self.stride + kc).checked_sub(pad).and_then(|s| src_row.get(s)) {
                        *out = *v;
                    }
                }
            }
        }
        let mut out = Map::zeros(self.outputs, rows, width);
        matmul(&self.layer.weight, cols, &mut out.values, self.outputs, k, n);
        add_bias(&mut out.values, &self.layer.bias, n, self.relu);
        out
    }
}

fn add_bias(values: &mut [f32], bias: &[f32], per_channel: usize, relu: bool) {
    for (channel, b) in values.chunks_exact_mut(per_channel).zip(bias) {
        for v in channel {
            *v += b;
            if relu {
                *v = v.max(0.0);
            }
        }
    }
}

/// A 2x2 transposed convolution of stride 2 (each input pixel paints a 2x2 block), then ReLU.
#[derive(Clone, Debug)]
struct Up {
    /// Per kernel position (dy, dx): the [out x in] matrix.
    taps: [Vec<f32>; 4],
    bias: Vec<f32>,
    inputs: usize,
    outputs: usize,
}

impl Up {
    fn load(w: &Weights, name: &str, inputs: usize, outputs: usize) -> Result<Self, PipelineError> {
        let layer = Layer::load(w, name, &[inputs, outputs, 2, 2], outputs)?;
        let tap = |t: usize| {
            let mut m = vec![0.0; outputs * inputs];
            for o in 0..outputs {
                for i in 0..inputs {
                    m[o * inputs + i] = layer.weight[(i * outputs + o) * 4 + t];
                }
            }
            m
        };
        Ok(Self { taps: [tap(0), tap(1), tap(2), tap(3)], bias: layer.bias, inputs, outputs })
    }

    fn forward(&self, x: &Map) -> Map {
        let n = x.rows * x.cols;
        let mut out = Map::zeros(self.outputs, x.rows * 2, x.cols * 2);
        let mut part = vec![0.0; self.outputs * n];
        for (t, tap) in self.taps.iter().enumerate() {
            matmul(tap, &x.values, &mut part, self.outputs, self.inputs, n);
            let (dy, dx) = (t / 2, t % 2);
            for o in 0..self.outputs {
                for r in 0..x.rows {
                    for c in 0..x.cols {
                        let v = part[o * n + r * x.cols + c];
                        out.values[(o * out.rows + 2 * r + dy) * out.cols + 2 * c + dx] = v;
                    }
                }
            }
        }
        add_bias(&mut out.values, &self.bias, out.rows * out.cols, true);
        out
    }
}

/// The whole network.
#[derive(Clone, Debug)]
pub struct Net {
    pfn: Layer,
    a: [Conv; 3],
    b: [Conv; 2],
    up: Up,
    h0: Conv,
    h1: Conv,
}

/// The time each part of one forward pass took (ms), for the benchmark's split.
#[derive(Clone, Copy, Debug, Default)]
pub struct NetTimes {
    pub pfn_ms: f64,
    pub backbone_ms: f64,
}

impl Net {
    pub fn load(w: &Weights) -> Result<Self, PipelineError> {
        Ok(Self {
            pfn: Layer::load(w, "pfn", &[PILLAR_CHANNELS, POINT_FEATURES], PILLAR_CHANNELS)?,
            a: [
                Conv::load(w, "a0", (PILLAR_CHANNELS, 24), 3, 2, true)?,
                Conv::load(w, "a1", (24, 24), 3, 1, true)?,
                Conv::load(w, "a2", (24, 24), 3, 1, true)?,
            ],
            b: [Conv::load(w, "b0", (24, 48), 3, 2, true)?, Conv::load(w, "b1", (48, 48), 3, 1, true)?],
            up: Up::load(w, "up", 48, 24)?,
            h0: Conv::load(w, "h0", (48, 32), 1, 1, true)?,
            h1: Conv::load(w, "h1", (32, HEAD_CHANNELS), 1, 1, false)?,
        })
    }

    /// The pillar feature net: per pillar, the max over its kept points of ReLU(W x + b).
    pub fn pillar_features(&self, pillars: &Pillars) -> Vec<f32> {
        let rows = pillars.features.len() / POINT_FEATURES;
        let mut h = vec![0.0; rows * PILLAR_CHANNELS];
        // [points x 8] * [8 x 32]: the weight is [32 x 8], so transpose it once.
        let w_t: Vec<f32> = (0..POINT_FEATURES * PILLAR_CHANNELS)
            .map(|i| self.pfn.weight[(i % PILLAR_CHANNELS) * POINT_FEATURES + i / PILLAR_CHANNELS])
            .collect();
        matmul(&pillars.features, &w_t, &mut h, rows, POINT_FEATURES, PILLAR_CHANNELS);
        let mut out = vec![0.0f32; pillars.len() * PILLAR_CHANNELS];
        let mut point_rows = h.chunks_exact(PILLAR_CHANNELS);
        for (feat, &n) in out.chunks_exact_mut(PILLAR_CHANNELS).zip(&pillars.counts) {
            // ReLU then max: starting from 0 is the ReLU.
            for point in point_rows.by_ref().take(usize::from(n)) {
                for ((f, v), b) in feat.iter_mut().zip(point).zip(&self.pfn.bias) {
                    *f = (*f).max(v + b);
                }
            }
        }
        out
    }

    /// The pillars' features scattered on the grid.
    pub fn canvas(pillars: &Pillars, features: &[f32]) -> Map {
        let mut canvas = Map::zeros(PILLAR_CHANNELS, GRID, GRID);
        for (&(iy, ix), f) in pillars.coords.iter().zip(features.chunks_exact(PILLAR_CHANNELS)) {
            for (c, v) in f.iter().enumerate() {
                canvas.values[(c * GRID + usize::from(iy)) * GRID + usize::from(ix)] = *v;
            }
        }
        canvas
    }

    /// Backbone and head: the canvas in, the 12 head channels over 48 x 48 cells out.
    pub fn backbone(&self, canvas: &Map) -> Map {
        let mut cols = Vec::new();
        let mut a = canvas.clone();
        for conv in &self.a {
            a = conv.forward(&a, &mut cols);
        }
        let mut b = a.clone();
        for conv in &self.b {
            b = conv.forward(&b, &mut cols);
        }
        let up = self.up.forward(&b);
        let mut cat = a;
        cat.channels += up.channels;
        cat.values.extend(&up.values);
        let h = self.h0.forward(&cat, &mut cols);
        self.h1.forward(&h, &mut cols)
    }
}
