//! A small ONNX graph interpreter on candle: the networks campro trains (YOLOX-Nano, read
//! from its batch-norm folded file; the enhancer's U-Net, built as ONNX) are run node by node
//! over the few operators they use (Conv, Relu, Sigmoid, Mul, Add, Concat, Slice, MaxPool,
//! Resize, Reshape, Transpose), with every Conv weight and bias a trainable [`Var`], and written
//! back as ONNX with the current weights, so what tract evaluates is what was trained.

use candle_core::{Result, Tensor, Var};
use prost::Message;
use std::collections::HashMap;
use std::path::Path;
use tract_onnx::pb;

/// Why an ONNX graph could not be read, interpreted or written.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    #[error("{path}: {message}")]
    Graph { path: String, message: String },
    #[error("tensor: {0}")]
    Tensor(#[from] candle_core::Error),
}

#[derive(Debug, Clone)]
enum Op {
    /// One axis, from `start` to `end` (clamped) by `step`.
    Slice {
        axis: usize,
        start: usize,
        end: i64,
        step: usize,
    },
    Concat(usize),
    Conv {
        w: String,
        b: Option<String>,
        stride: usize,
        pad: usize,
        depthwise: bool,
    },
    Sigmoid,
    Relu,
    /// `x · σ(x)`: a Sigmoid and the Mul of its input by it, fused at load time.
    Silu,
    Mul,
    /// Multiplication by a constant scalar.
    Scale(f32),
    Add,
    /// Stride-1 max pooling, `k` x `k`, padding (k − 1) / 2.
    MaxPool(usize),
    /// Nearest-neighbour upsampling by an integer factor.
    Upsample(usize),
    /// (B, C, H, W) → (B, C, H·W).
    Flatten,
    /// (B, ...) → (B, rest): ONNX Flatten on axis 1, or a Reshape to two dimensions (a face
    /// model's export fixes it to (1, −1); read per image).
    FlattenBatch,
    /// PReLU with one trainable slope per channel (initializer `slope`, C values).
    Prelu {
        slope: String,
    },
    /// (B, C, N) → (B, N, C).
    Transpose,
}

#[derive(Debug, Clone)]
struct Node {
    op: Op,
    inputs: Vec<String>,
    output: String,
}

/// An ONNX graph with trainable convolutions.
pub struct OnnxNet {
    nodes: Vec<Node>,
    /// The graph's (first non-constant) input.
    pub(crate) input: String,
    /// The graph's first output.
    pub(crate) output: String,
    /// Conv weights and biases by initializer name, in graph order.
    pub(crate) params: Vec<(String, Var)>,
    pub(crate) index: HashMap<String, usize>,
    /// The file as read, to write back with new weights.
    model: pb::ModelProto,
}

fn ints(t: &pb::TensorProto) -> Vec<i64> {
    if !t.int64_data.is_empty() {
        return t.int64_data.clone();
    }
    t.raw_data.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes"))).collect()
}

fn floats(t: &pb::TensorProto) -> Vec<f32> {
    if !t.float_data.is_empty() {
        return t.float_data.clone();
    }
    t.raw_data.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
}

/// The ONNX file at `path` (read capped at 256 MiB) and its path as shown in errors.
fn read_model(path: &Path) -> std::result::Result<(pb::ModelProto, String), GraphError> {
    let p = path.display().to_string();
    let bytes = campro::file::read_capped(path, 256 << 20, "an ONNX model")
        .map_err(|e| GraphError::Io { path: p.clone(), message: e.reason() })?;
    let model = pb::ModelProto::decode(bytes.as_slice())
        .map_err(|e| GraphError::Graph { path: p.clone(), message: format!("not an ONNX model: {e}") })?;
    Ok((full_precision(model), p))
}

/// Writes `model` at `path` (temporary file, then rename).
fn write_model(path: &Path, model: &pb::ModelProto) -> std::result::Result<(), GraphError> {
    campro::file::atomic::write(path, &model.encode_to_vec(), true)
        .map_err(|e| GraphError::Io { path: path.display().to_string(), message: e.to_string() })
}

/// The f32 initializers of the ONNX file at `path` by name (a
/// tensor whose data does not fill its shape is an error naming it). Other types are left
/// out.
pub fn f32_initializers(
    path: &Path,
    dev: &candle_core::Device,
) -> std::result::Result<HashMap<String, Tensor>, GraphError> {
    let (model, p) = read_model(path)?;
    let bad = |m: String| GraphError::Graph { path: p.clone(), message: m };
    let graph = model.graph.ok_or_else(|| bad("no graph".into()))?;
    let mut out = HashMap::new();
    for t in graph.initializer.iter().filter(|t| t.data_type == 1) {
        let dims: Vec<usize> = t.dims.iter().map(|&d| usize::try_from(d).unwrap_or(usize::MAX)).collect();
        let v = floats(t);
        if dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)) != Some(v.len()) {
            return Err(bad(format!("initializer {}: {} values for shape {:?}", t.name, v.len(), t.dims)));
        }
        let tensor = Tensor::from_vec(v, dims, dev).map_err(|e| bad(format!("initializer {}: {e}", t.name)))?;
        out.insert(t.name.clone(), tensor);
    }
    Ok(out)
}

/// Smallest f32 initializer [`half_precision`] stores at half precision (values): smaller
/// ones (biases, scales, shapes) cost little and stay exact.
pub const HALF_MIN_VALUES: usize = 64;

/// `model` with its weights stored at half precision: every f32 initializer of at least
/// [`HALF_MIN_VALUES`] values, all finite and within f16's range (|v| <= 65,504), becomes
/// an f16 initializer `NAME.f16` and a `Cast` to f32 writing `NAME` (first in the graph, so
/// readers see the same names and types; tract folds the casts when it optimises). Each
/// weight is rounded to the nearest f16: a relative error of at most 2^-11, or an absolute
/// one of at most 2^-25 below f16's normal range (6.1e-5). Halves the file of a
/// convolutional network (YOLOX-Nano: 3.6 to 1.8 MB); others are returned unchanged.
pub fn half_precision(mut model: pb::ModelProto) -> pb::ModelProto {
    let Some(graph) = model.graph.as_mut() else { return model };
    let mut casts = Vec::new();
    for t in graph.initializer.iter_mut().filter(|t| t.data_type == 1) {
        let v = floats(t);
        if v.len() < HALF_MIN_VALUES || !v.iter().all(|x| x.is_finite() && x.abs() <= f32::from(half::f16::MAX)) {
            continue;
        }
        let name = std::mem::take(&mut t.name);
        t.name = format!("{name}.f16");
        t.data_type = 10;
        t.float_data.clear();
        t.raw_data = v.iter().flat_map(|&x| half::f16::from_f32(x).to_le_bytes()).collect();
        // A graph input of the same name (ONNX before IR 4 lists initializers there too)
        // would shadow the cast's output.
        graph.input.retain(|i| i.name != name);
        casts.push(pb::NodeProto {
            name: format!("{name}.cast"),
            op_type: "Cast".into(),
            input: vec![t.name.clone()],
            output: vec![name],
            attribute: vec![pb::AttributeProto { name: "to".into(), r#type: 2, i: 1, ..Default::default() }],
            ..Default::default()
        });
    }
    casts.append(&mut graph.node);
    graph.node = casts;
    model
}

/// [`half_precision`] undone for training: each `Cast` to f32 of an f16 initializer becomes
/// an f32 initializer of the cast's output name holding the same values (widening is
/// exact), so a shipped detector can be fine-tuned further. Other graphs are unchanged.
pub fn full_precision(mut model: pb::ModelProto) -> pb::ModelProto {
    let Some(graph) = model.graph.as_mut() else { return model };
    let halves: HashMap<String, pb::TensorProto> =
        graph.initializer.iter().filter(|t| t.data_type == 10).map(|t| (t.name.clone(), t.clone())).collect();
    let mut widened = Vec::new();
    graph.node.retain(|n| {
        let to_f32 = n.attribute.iter().any(|a| a.name == "to" && a.i == 1);
        match (n.op_type.as_str(), n.input.first().and_then(|i| halves.get(i)), &n.output[..]) {
            ("Cast", Some(t), [out]) if to_f32 && n.input.len() == 1 => {
                let v: Vec<f32> =
                    t.raw_data.chunks_exact(2).map(|c| f32::from(half::f16::from_le_bytes([c[0], c[1]]))).collect();
                widened.push((t.name.clone(), f32_tensor(out, t.dims.clone(), &v)));
                false
            }
            _ => true,
        }
    });
    let gone: Vec<&String> = widened.iter().map(|(from, _)| from).collect();
    graph.initializer.retain(|t| !gone.contains(&&t.name));
    graph.initializer.extend(widened.into_iter().map(|(_, t)| t));
    model
}

/// An f32 initializer `name` of shape `dims` (raw little-endian data).
pub fn f32_tensor(name: &str, dims: Vec<i64>, v: &[f32]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims,
        data_type: 1,
        raw_data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ..Default::default()
    }
}

/// An integer-list attribute.
pub fn ints_attr(name: &str, v: Vec<i64>) -> pb::AttributeProto {
    pb::AttributeProto { name: name.into(), r#type: 7, ints: v, ..Default::default() }
}

/// A string attribute.
pub fn string_attr(name: &str, v: &str) -> pb::AttributeProto {
    pb::AttributeProto { name: name.into(), r#type: 3, s: v.as_bytes().to_vec(), ..Default::default() }
}

/// A node named after its one output.
pub fn node(op: &str, inputs: &[&str], output: &str, attribute: Vec<pb::AttributeProto>) -> pb::NodeProto {
    pb::NodeProto {
        name: format!("{op}_{output}"),
        op_type: op.into(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.into()],
        attribute,
        ..Default::default()
    }
}

/// The attributes of a square `k` x `k` convolution with symmetric padding.
pub fn conv_attrs(k: i64, stride: i64, pad: i64) -> Vec<pb::AttributeProto> {
    vec![
        ints_attr("kernel_shape", vec![k, k]),
        ints_attr("strides", vec![stride, stride]),
        ints_attr("pads", vec![pad, pad, pad, pad]),
        ints_attr("dilations", vec![1, 1]),
    ]
}

impl OnnxNet {
    /// Reads the ONNX file; any operator or attribute outside what YOLOX, the shared face
    /// models and the enhancer's U-Net use is an error naming the node.
    pub fn load(path: &Path, dev: &candle_core::Device) -> std::result::Result<Self, GraphError> {
        let (model, p) = read_model(path)?;
        Self::from_model(model, p, dev)
    }

    pub fn from_model(
        model: pb::ModelProto,
        p: String,
        dev: &candle_core::Device,
    ) -> std::result::Result<Self, GraphError> {
        let bad = |m: String| GraphError::Graph { path: p.clone(), message: m };
        let graph = model.graph.as_ref().ok_or_else(|| bad("no graph".into()))?;
        let inits: HashMap<&str, &pb::TensorProto> = graph.initializer.iter().map(|t| (t.name.as_str(), t)).collect();
        let int_of = |name: &str| -> std::result::Result<i64, GraphError> {
            let t = inits.get(name).ok_or_else(|| bad(format!("{name}: expected a constant")))?;
            ints(t).first().copied().ok_or_else(|| bad(format!("{name}: empty constant")))
        };
        let mut nodes = Vec::new();
        let mut params = Vec::new();
        for n in &graph.node {
            let what = format!("node {} ({})", n.name, n.op_type);
            let attr = |name: &str| n.attribute.iter().find(|a| a.name == name);
            let attr_ints = |name: &str| attr(name).map(|a| a.ints.clone()).unwrap_or_default();
            let data: Vec<String> =
                n.input.iter().filter(|i| !inits.contains_key(i.as_str()) && !i.is_empty()).cloned().collect();
            let op = match n.op_type.as_str() {
                "Slice" => {
                    let arg = |k: usize| int_of(&n.input[k]);
                    if n.input.len() != 5 {
                        return Err(bad(format!("{what}: expected data, starts, ends, axes, steps")));
                    }
                    let (start, end, axis, step) = (arg(1)?, arg(2)?, arg(3)?, arg(4)?);
                    if start < 0 || !(0..4).contains(&axis) || step < 1 {
                        return Err(bad(format!("{what}: start {start}, axis {axis}, step {step} unsupported")));
                    }
                    Op::Slice { axis: axis as usize, start: start as usize, end, step: step as usize }
                }
                "Concat" => Op::Concat(attr("axis").map_or(0, |a| a.i) as usize),
                "Conv" => {
                    let w = inits
                        .get(n.input[1].as_str())
                        .ok_or_else(|| bad(format!("{what}: weight is not a constant")))?;
                    let (stride, pads, dil, group) = (
                        attr_ints("strides"),
                        attr_ints("pads"),
                        attr_ints("dilations"),
                        attr("group").map_or(1, |a| a.i),
                    );
                    let pad = pads.first().copied().unwrap_or(0);
                    if pads.iter().any(|&q| q != pad)
                        || dil.iter().any(|&d| d != 1)
                        || stride.len() != 2
                        || stride[0] != stride[1]
                    {
                        return Err(bad(format!("{what}: only symmetric padding, square strides and no dilation")));
                    }
                    let depthwise = group != 1;
                    if depthwise && (w.dims.get(1) != Some(&1) || w.dims[0] != group) {
                        return Err(bad(format!("{what}: grouped convolution that is not depthwise")));
                    }
                    let b = n.input.get(2).cloned();
                    for name in std::iter::once(&n.input[1]).chain(b.iter()) {
                        let t = inits[name.as_str()];
                        let dims: Vec<usize> = t.dims.iter().map(|&d| d as usize).collect();
                        params.push((name.clone(), Var::from_vec(floats(t), dims, dev)?));
                    }
                    Op::Conv { w: n.input[1].clone(), b, stride: stride[0] as usize, pad: pad as usize, depthwise }
                }
                "Sigmoid" => Op::Sigmoid,
                "Relu" => Op::Relu,
                "Mul" => match n.input.iter().find_map(|i| inits.get(i.as_str())) {
                    Some(c) if data.len() == 1 && c.dims.iter().all(|&d| d == 1) && floats(c).len() == 1 => {
                        Op::Scale(floats(c)[0])
                    }
                    Some(_) => return Err(bad(format!("{what}: a constant factor must be a scalar"))),
                    None => Op::Mul,
                },
                "Add" => Op::Add,
                "MaxPool" => {
                    let k = attr_ints("kernel_shape");
                    let (s, pads) = (attr_ints("strides"), attr_ints("pads"));
                    if k.len() != 2
                        || k[0] != k[1]
                        || k[0] % 2 == 0
                        || s.iter().any(|&v| v != 1)
                        || pads.iter().any(|&q| q != k[0] / 2)
                    {
                        return Err(bad(format!("{what}: only odd square stride-1 'same' pooling")));
                    }
                    Op::MaxPool(k[0] as usize)
                }
                "Resize" => {
                    let mode = attr("mode").map(|a| String::from_utf8_lossy(&a.s).to_string()).unwrap_or_default();
                    let scales =
                        n.input.get(2).and_then(|s| inits.get(s.as_str())).map(|t| floats(t)).unwrap_or_default();
                    let f = scales.get(2).copied().unwrap_or(0.0);
                    if mode != "nearest" || scales.len() != 4 || scales[3] != f || f.fract() != 0.0 || f < 1.0 {
                        return Err(bad(format!(
                            "{what}: only nearest upsampling by an integer factor (mode {mode}, scales {scales:?})"
                        )));
                    }
                    Op::Upsample(f as usize)
                }
                "Reshape" => match n.input.get(1).and_then(|s| inits.get(s.as_str())).map(|t| ints(t).len()) {
                    Some(2) => Op::FlattenBatch,
                    _ => Op::Flatten,
                },
                "Flatten" => {
                    if attr("axis").map_or(1, |a| a.i) != 1 {
                        return Err(bad(format!("{what}: only axis 1")));
                    }
                    Op::FlattenBatch
                }
                "PRelu" => {
                    let s = n
                        .input
                        .get(1)
                        .and_then(|s| inits.get(s.as_str()))
                        .ok_or_else(|| bad(format!("{what}: slope is not a constant")))?;
                    let v = floats(s);
                    if s.dims.iter().skip(1).any(|&d| d != 1) || v.is_empty() {
                        return Err(bad(format!("{what}: only one slope per channel, got {:?}", s.dims)));
                    }
                    if !params.iter().any(|(name, _)| name == &s.name) {
                        params.push((s.name.clone(), Var::from_vec(v.clone(), v.len(), dev)?));
                    }
                    Op::Prelu { slope: s.name.clone() }
                }
                "Transpose" => {
                    if attr_ints("perm") != [0, 2, 1] {
                        return Err(bad(format!("{what}: only perm [0, 2, 1]")));
                    }
                    Op::Transpose
                }
                other => return Err(bad(format!("{what}: operator {other} is not supported"))),
            };
            let output = n.output.first().cloned().ok_or_else(|| bad(format!("{what}: no output")))?;
            nodes.push(Node { op, inputs: data, output });
        }
        let input = graph
            .input
            .iter()
            .map(|i| i.name.clone())
            .find(|n| !inits.contains_key(n.as_str()))
            .ok_or_else(|| bad("no input".into()))?;
        let output = graph.output.first().map(|o| o.name.clone()).ok_or_else(|| bad("no output".into()))?;
        let index = params.iter().enumerate().map(|(i, (n, _))| (n.clone(), i)).collect();
        fuse_silu(&mut nodes, &output);
        Ok(Self { nodes, input, output, params, index, model })
    }

    /// Every trainable tensor (conv weights and biases).
    pub fn vars(&self) -> Vec<Var> {
        self.params.iter().map(|(_, v)| v.clone()).collect()
    }

    /// Every trainable tensor with its ONNX initializer name.
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        self.params.clone()
    }

    /// The graph's output for input `x`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.run(x, None)?
            .remove(self.output.as_str())
            .ok_or_else(|| candle_core::Error::Msg(format!("{} not computed", self.output)))
    }

    fn param(&self, name: &str) -> &Var {
        &self.params[self.index[name]].1
    }

    /// Interprets the graph on `x`, up to the node writing `until` (all of it if None).
    pub fn run(&self, x: &Tensor, until: Option<&str>) -> Result<HashMap<&str, Tensor>> {
        let mut values: HashMap<&str, Tensor> = HashMap::new();
        values.insert(&self.input, x.clone());
        for n in &self.nodes {
            if until.is_some_and(|u| values.contains_key(u)) {
                break;
            }
            let arg = |k: usize| -> Result<&Tensor> {
                values
                    .get(n.inputs[k].as_str())
                    .ok_or_else(|| candle_core::Error::Msg(format!("{} not computed", n.inputs[k])))
            };
            let y = match &n.op {
                Op::Slice { axis, start, end, step } => {
                    let x = arg(0)?;
                    let len = x.dim(*axis)?;
                    let end = (*end).clamp(0, len as i64) as usize;
                    let x = x.narrow(*axis, *start, end.saturating_sub(*start))?;
                    crate::conv::subsample(&x, *axis, *step)?
                }
                Op::Concat(axis) => Tensor::cat(&(0..n.inputs.len()).map(arg).collect::<Result<Vec<_>>>()?, *axis)?,
                Op::Conv { w, b, stride, pad, depthwise } => {
                    let w = self.param(w).as_tensor();
                    let y = if *depthwise {
                        crate::depthwise::depthwise(arg(0)?, w, *stride, *pad)?
                    } else {
                        crate::conv::conv2d(arg(0)?, w, *stride, *pad)?
                    };
                    match b {
                        Some(b) => crate::channel::channel_bias(&y, self.param(b).as_tensor())?,
                        None => y,
                    }
                }
                Op::Sigmoid => candle_nn::ops::sigmoid(arg(0)?)?,
                Op::Relu => crate::activation::relu(arg(0)?)?,
                Op::Silu => crate::activation::silu(arg(0)?)?,
                Op::Mul => arg(0)?.broadcast_mul(arg(1)?)?,
                Op::Scale(c) => (arg(0)? * *c as f64)?,
                Op::Add => arg(0)?.broadcast_add(arg(1)?)?,
                Op::MaxPool(k) => max_pool_same(arg(0)?, *k)?,
                Op::Upsample(f) => {
                    let (_, _, h, w) = arg(0)?.dims4()?;
                    arg(0)?.upsample_nearest2d(h * f, w * f)?
                }
                Op::Flatten => arg(0)?.flatten_from(2)?,
                Op::FlattenBatch => arg(0)?.flatten_from(1)?,
                Op::Prelu { slope } => crate::activation::prelu(arg(0)?, self.param(slope).as_tensor())?,
                Op::Transpose => arg(0)?.transpose(1, 2)?.contiguous()?,
            };
            values.insert(&n.output, y);
        }
        Ok(values)
    }

    /// The model with the current weights, encoded as an ONNX file.
    pub fn onnx_bytes(&self) -> Result<Vec<u8>> {
        Ok(self.current()?.encode_to_vec())
    }

    /// Writes the model with the current weights as ONNX (temporary file, then rename).
    pub fn save_onnx(&self, path: &Path) -> std::result::Result<(), GraphError> {
        write_model(path, &self.current()?)
    }

    /// Writes the model with the current weights as ONNX at half precision
    /// ([`half_precision`]; temporary file, then rename).
    pub fn save_onnx_half(&self, path: &Path) -> std::result::Result<(), GraphError> {
        write_model(path, &half_precision(self.current()?))
    }

    /// The ONNX model with the current weights.
    pub fn current(&self) -> Result<pb::ModelProto> {
        let mut model = self.model.clone();
        let graph = model.graph.as_mut().expect("checked in load");
        for t in graph.initializer.iter_mut() {
            if let Some(&i) = self.index.get(&t.name) {
                let v: Vec<f32> = self.params[i].1.as_tensor().flatten_all()?.to_vec1()?;
                t.float_data.clear();
                t.raw_data = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            }
        }
        Ok(model)
    }
}

/// Replaces each `s = Sigmoid(x)` followed by `Mul(x, s)` (either order), where nothing else
/// reads `s` and `s` is not the graph's output, by one `Silu(x)` node writing the Mul's output.
fn fuse_silu(nodes: &mut Vec<Node>, graph_output: &str) {
    let mut i = 0;
    while i < nodes.len() {
        if matches!(nodes[i].op, Op::Sigmoid) && nodes[i].output != graph_output {
            let (x, s) = (nodes[i].inputs[0].clone(), nodes[i].output.clone());
            let readers: Vec<usize> = (0..nodes.len()).filter(|&j| nodes[j].inputs.contains(&s)).collect();
            if let [j] = readers[..] {
                let m = &nodes[j];
                let pair = m.inputs.len() == 2
                    && ((m.inputs[0] == x && m.inputs[1] == s) || (m.inputs[0] == s && m.inputs[1] == x));
                if matches!(m.op, Op::Mul) && pair && j > i {
                    nodes[j] = Node { op: Op::Silu, inputs: vec![x], output: nodes[j].output.clone() };
                    nodes.remove(i);
                    continue;
                }
            }
        }
        i += 1;
    }
}

/// Stride-1 `k` x `k` max pooling with (k − 1)/2 padding that never wins (ONNX's −∞), as two
/// separable passes of element-wise maxima (differentiable; candle's pooling backward needs
/// stride = kernel).
fn max_pool_same(x: &Tensor, k: usize) -> Result<Tensor> {
    let r = k / 2;
    let pass = |x: &Tensor, dim: usize| -> Result<Tensor> {
        let n = x.dim(dim)?;
        let mut shape = x.dims().to_vec();
        shape[dim] = r;
        let wall = Tensor::full(f32::MIN, shape, x.device())?;
        let padded = Tensor::cat(&[&wall, x, &wall], dim)?;
        let mut m = padded.narrow(dim, 0, n)?;
        for s in 1..k {
            m = m.maximum(&padded.narrow(dim, s, n)?)?;
        }
        Ok(m)
    };
    pass(&pass(x, 3)?, 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tract_onnx::prelude::*;

    /// A one-convolution model: 8 filters of 3 x 3 x 3 (216 weights) and 8 biases.
    fn conv_model(weights: &[f32], bias: &[f32]) -> pb::ModelProto {
        let io = |name: &str, dims: &[i64]| pb::ValueInfoProto {
            name: name.into(),
            r#type: Some(pb::TypeProto {
                value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                    elem_type: 1,
                    shape: Some(pb::TensorShapeProto {
                        dim: dims
                            .iter()
                            .map(|&d| pb::tensor_shape_proto::Dimension {
                                value: Some(pb::tensor_shape_proto::dimension::Value::DimValue(d)),
                                ..Default::default()
                            })
                            .collect(),
                    }),
                })),
                ..Default::default()
            }),
            ..Default::default()
        };
        pb::ModelProto {
            ir_version: 7,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 13 }],
            graph: Some(pb::GraphProto {
                name: "conv".into(),
                node: vec![pb::NodeProto {
                    op_type: "Conv".into(),
                    input: vec!["x".into(), "w".into(), "b".into()],
                    output: vec!["y".into()],
                    ..Default::default()
                }],
                initializer: vec![f32_tensor("w", vec![8, 3, 3, 3], weights), f32_tensor("b", vec![8], bias)],
                input: vec![io("x", &[1, 3, 6, 6])],
                output: vec![io("y", &[1, 8, 4, 4])],
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    fn run(model: &pb::ModelProto, x: &[f32]) -> Vec<f32> {
        let plan =
            tract_onnx::onnx().model_for_proto_model(model).unwrap().into_optimized().unwrap().into_runnable().unwrap();
        let out = plan.run(tvec!(tract_onnx::prelude::Tensor::from_shape(&[1, 3, 6, 6], x).unwrap().into())).unwrap();
        out[0].clone().into_tensor().try_as_plain_ram().and_then(|v| v.as_slice::<f32>()).unwrap().to_vec()
    }

    #[test]
    fn half_precision_rounds_the_weights_and_keeps_the_graph_s_meaning() {
        // Weights across f16's normal range and below it; biases too few to convert.
        let weights: Vec<f32> = (0..216).map(|i| (i as f32 * 0.37).sin() * 10f32.powi(i % 7 - 5)).collect();
        let bias: Vec<f32> = (0..8).map(|i| i as f32 * 0.1 - 0.3).collect();
        let x: Vec<f32> = (0..108).map(|i| (i as f32 * 0.11).cos()).collect();
        let full = conv_model(&weights, &bias);
        let half = half_precision(full.clone());
        let g = half.graph.as_ref().unwrap();
        // The weights became f16 behind a cast; the biases stayed f32 under their name.
        let w = g.initializer.iter().find(|t| t.name == "w.f16").expect("w stored as w.f16");
        assert_eq!((w.data_type, w.raw_data.len()), (10, 2 * 216));
        assert!(g.initializer.iter().any(|t| t.name == "b" && t.data_type == 1));
        assert_eq!((g.node[0].op_type.as_str(), g.node[0].output[0].as_str()), ("Cast", "w"));
        // Each stored weight is the nearest f16: within 2^-11 relative or 2^-25 absolute.
        for (c, &v) in w.raw_data.chunks_exact(2).zip(&weights) {
            let h = f32::from(half::f16::from_le_bytes([c[0], c[1]]));
            assert!((h - v).abs() <= (v.abs() * 2f32.powi(-11)).max(2f32.powi(-25)), "{v} stored as {h}");
        }
        // Both run the same convolution: the half model equals the full one with its
        // weights rounded (the second implementation), and differs from the original by
        // at most the rounding times the input's size (27 products of |x| <= 1).
        let rounded: Vec<f32> = weights.iter().map(|&v| f32::from(half::f16::from_f32(v))).collect();
        let (a, b, c) = (run(&full, &x), run(&half, &x), run(&conv_model(&rounded, &bias), &x));
        for ((a, b), c) in a.iter().zip(&b).zip(&c) {
            assert!((b - c).abs() <= 1e-6 * (1.0 + c.abs()), "{b} against {c}");
            assert!((a - b).abs() <= 27.0 * 2f32.powi(-11) * 0.5 * 10.0 + 1e-6, "{a} against {b}");
        }
        // Undone for training: the cast folded into an f32 `w` holding the f16 values.
        let back = full_precision(half.clone());
        let g = back.graph.as_ref().unwrap();
        assert_eq!(g.node.len(), 1, "only the convolution is left");
        let w = g.initializer.iter().find(|t| t.name == "w").expect("w is f32 again");
        assert_eq!((w.data_type, floats(w)), (1, rounded.clone()));
        assert!(g.initializer.iter().all(|t| t.data_type == 1) && g.initializer.len() == 2);
        assert_eq!(run(&back, &x), b);
        // Out of range or non-finite weights stay f32.
        let mut big = weights.clone();
        big[3] = 70_000.0;
        let kept = half_precision(conv_model(&big, &bias));
        assert!(kept.graph.unwrap().initializer.iter().all(|t| t.data_type == 1));
    }
}
