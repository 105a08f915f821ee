//! Gradient-boosted trees read from an STPW file (docs/detect.md, "Method (`trees`)"): every
//! node and index is checked when the file is read, so a bad file is an error and a walk down
//! a tree always ends.

use super::inputs::INPUTS;
use crate::detect::pillars::weights::Weights;
use crate::PipelineError;

/// Classes the trees score: not a person, then the postures.
pub const CLASSES: usize = 4;

/// One node: a leaf when `feature` is None.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Node {
    feature: Option<u16>,
    threshold: f32,
    left: u32,
    right: u32,
    value: f32,
}

/// A multiclass ensemble: each tree adds its leaf's value to its class's logit.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeModel {
    nodes: Vec<Node>,
    /// Root node and class of each tree.
    trees: Vec<(u32, u8)>,
    base: [f32; CLASSES],
}

fn bad(reason: String) -> PipelineError {
    PipelineError::BadFile { format: "STPW trees", reason }
}

/// An f32 that must be a whole number in `0..limit`.
fn index(v: f32, limit: usize, what: &str) -> Result<usize, PipelineError> {
    let ok = v >= 0.0 && v.fract() == 0.0 && (v as usize) < limit;
    ok.then_some(v as usize).ok_or_else(|| bad(format!("{what} {v} is not an index below {limit}")))
}

impl TreeModel {
    /// The trees of a weights file with the tensors `inputs` (\[1\]: the input length it was
    /// trained for), `base` (\[4\]), `tree_root`, `tree_class` (\[T\]), and `node_feature` (-1 for a
    /// leaf), `node_threshold`, `node_left`, `node_right`, `node_value` (\[N\]). A split sends
    /// `x <= threshold` left; children come after their parent, so every walk ends.
    pub fn from_weights(w: &Weights) -> Result<Self, PipelineError> {
        let inputs = w.get("inputs", &[1])?;
        if inputs[0] as usize != INPUTS {
            return Err(bad(format!("trained for {} inputs, this program makes {INPUTS}", inputs[0])));
        }
        let base_v = w.get("base", &[CLASSES])?;
        let n = dims_of(w, "node_feature")?;
        let t = dims_of(w, "tree_root")?;
        let (feature, threshold) = (w.get("node_feature", &[n])?, w.get("node_threshold", &[n])?);
        let (left, right, value) = (w.get("node_left", &[n])?, w.get("node_right", &[n])?, w.get("node_value", &[n])?);
        let mut nodes = Vec::with_capacity(n);
        for i in 0..n {
            nodes.push(node(i, n, feature[i], threshold[i], left[i], right[i], value[i])?);
        }
        let (root, class) = (w.get("tree_root", &[t])?, w.get("tree_class", &[t])?);
        let trees = root
            .iter()
            .zip(class)
            .map(|(&r, &c)| Ok((index(r, n, "tree root")? as u32, index(c, CLASSES, "tree class")? as u8)))
            .collect::<Result<Vec<_>, PipelineError>>()?;
        let mut base = [0.0; CLASSES];
        base.copy_from_slice(base_v);
        Ok(Self { nodes, trees, base })
    }

    /// The probability of each class (softmax of the logits).
    pub fn predict(&self, x: &[f32; INPUTS]) -> [f32; CLASSES] {
        let mut logit = self.base;
        for &(root, class) in &self.trees {
            logit[usize::from(class)] += self.leaf(root, x);
        }
        // Leaf values are finite, but their sum may not be: such a file says nothing.
        if !logit.iter().all(|l| l.is_finite()) {
            let mut none = [0.0; CLASSES];
            none[0] = 1.0;
            return none;
        }
        let top = logit.iter().copied().fold(f32::MIN, f32::max);
        let e = logit.map(|l| (l - top).exp());
        let sum: f32 = e.iter().sum();
        e.map(|v| v / sum)
    }

    fn leaf(&self, root: u32, x: &[f32; INPUTS]) -> f32 {
        let mut at = root as usize;
        // Children come after their parent (checked when read): at most one step per node.
        while let Some(node) = self.nodes.get(at) {
            match node.feature {
                None => return node.value,
                Some(f) => {
                    let go_left = x.get(usize::from(f)).is_some_and(|&v| v <= node.threshold);
                    at = if go_left { node.left } else { node.right } as usize;
                }
            }
        }
        0.0
    }
}

fn dims_of(w: &Weights, name: &str) -> Result<usize, PipelineError> {
    match w.tensor(name)?.dims.as_slice() {
        [n] if *n > 0 => Ok(*n),
        d => Err(bad(format!("{name} is {d:?}, expected one non-empty dimension"))),
    }
}

fn node(
    i: usize,
    n: usize,
    feature: f32,
    threshold: f32,
    left: f32,
    right: f32,
    value: f32,
) -> Result<Node, PipelineError> {
    if feature == -1.0 {
        return Ok(Node { feature: None, threshold, left: 0, right: 0, value });
    }
    let f = index(feature, INPUTS, "node feature")? as u16;
    let (l, r) = (index(left, n, "left child")?, index(right, n, "right child")?);
    if l <= i || r <= i {
        return Err(bad(format!("node {i}: a child ({l}, {r}) before its parent")));
    }
    Ok(Node { feature: Some(f), threshold, left: l as u32, right: r as u32, value })
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::detect::pillars::weights::{encode, Tensor};

    fn t(name: &str, values: Vec<f32>) -> Tensor {
        Tensor { name: name.into(), dims: vec![values.len()], values }
    }

    /// Two stumps: "not a person" unless input 4 (height) is above 1 m, then upright.
    pub(crate) fn stumps() -> Vec<Tensor> {
        vec![
            t("inputs", vec![INPUTS as f32]),
            t("base", vec![0.0, 0.0, 0.0, 0.0]),
            t("tree_root", vec![0.0, 3.0]),
            t("tree_class", vec![0.0, 1.0]),
            t("node_feature", vec![4.0, -1.0, -1.0, 4.0, -1.0, -1.0]),
            t("node_threshold", vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
            t("node_left", vec![1.0, 0.0, 0.0, 4.0, 0.0, 0.0]),
            t("node_right", vec![2.0, 0.0, 0.0, 5.0, 0.0, 0.0]),
            t("node_value", vec![0.0, 3.0, -3.0, 0.0, -3.0, 3.0]),
        ]
    }

    #[test]
    fn stumps_split_on_their_feature() {
        let m = TreeModel::from_weights(&Weights::parse(&encode(&stumps())).unwrap()).unwrap();
        let mut x = [0.0f32; INPUTS];
        x[4] = 0.5;
        let low = m.predict(&x);
        x[4] = 1.7;
        let tall = m.predict(&x);
        assert!(low[0] > 0.9 && tall[1] > 0.9, "{low:?} {tall:?}");
        assert!((tall.iter().sum::<f32>() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn a_child_before_its_parent_or_out_of_range_is_refused() {
        for (tensor, at, v) in
            [("node_left", 0, 0.0), ("node_right", 3, 9.0), ("node_feature", 0, 999.0), ("tree_class", 1, 4.0)]
        {
            let mut ts = stumps();
            ts.iter_mut().find(|x| x.name == tensor).unwrap().values[at] = v;
            let e = TreeModel::from_weights(&Weights::parse(&encode(&ts)).unwrap());
            assert!(e.is_err(), "{tensor}[{at}] = {v} was taken");
        }
        let mut ts = stumps();
        ts[0].values[0] = 3.0;
        assert!(TreeModel::from_weights(&Weights::parse(&encode(&ts)).unwrap()).is_err(), "wrong input count");
    }
}
