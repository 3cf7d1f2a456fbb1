//! The adversary's softmax linear classifier over face embeddings (the paper's "Linear"):
//! logits = Wᵀx + b, trained full-batch with Adam on cross-entropy plus L2 weight decay,
//! starting from the class-mean embeddings (scaled), so a few dozen steps suffice.

use ndarray::{Array1, Array2, Axis};

/// Training settings.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct LinearOptions {
    pub iterations: usize,
    pub learning_rate: f32,
    pub weight_decay: f32,
    /// Scale of the class-mean initialisation (an inverse temperature on cosines).
    pub init_scale: f32,
}

impl Default for LinearOptions {
    fn default() -> Self {
        Self { iterations: 60, learning_rate: 0.01, weight_decay: 5e-4, init_scale: 16.0 }
    }
}

/// A trained classifier: `w` is d x classes.
pub struct Linear {
    pub w: Array2<f32>,
    pub b: Array1<f32>,
}

fn softmax_rows(z: &mut Array2<f32>) {
    for mut row in z.rows_mut() {
        let m = row.fold(f32::NEG_INFINITY, |a, &v| a.max(v));
        row.mapv_inplace(|v| (v - m).exp());
        let s = row.sum();
        row.mapv_inplace(|v| v / s);
    }
}

/// Mean cross-entropy of the classifier on (x, y).
pub fn loss(model: &Linear, x: &Array2<f32>, y: &[usize]) -> f32 {
    let mut p = x.dot(&model.w) + &model.b;
    softmax_rows(&mut p);
    -y.iter().enumerate().map(|(i, &c)| p[[i, c]].max(1e-30).ln()).sum::<f32>() / y.len() as f32
}

/// Trains on rows of `x` (n x d) with labels `y` in 0..classes.
pub fn train(x: &Array2<f32>, y: &[usize], classes: usize, o: &LinearOptions) -> Linear {
    let (n, d) = x.dim();
    assert_eq!(n, y.len());
    let mut w = Array2::<f32>::zeros((d, classes));
    let mut count = vec![0f32; classes];
    for (row, &c) in x.rows().into_iter().zip(y) {
        let mut col = w.column_mut(c);
        col += &row;
        count[c] += 1.0;
    }
    for (c, mut col) in w.columns_mut().into_iter().enumerate() {
        let norm = col.dot(&col).sqrt();
        if count[c] > 0.0 && norm > 0.0 {
            col.mapv_inplace(|v| v / norm * o.init_scale);
        }
    }
    let mut model = Linear { w, b: Array1::zeros(classes) };
    let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
    let (mut mw, mut vw) = (Array2::<f32>::zeros((d, classes)), Array2::<f32>::zeros((d, classes)));
    let (mut mb, mut vb) = (Array1::<f32>::zeros(classes), Array1::<f32>::zeros(classes));
    for t in 1..=o.iterations {
        let mut g = x.dot(&model.w) + &model.b;
        softmax_rows(&mut g);
        for (i, &c) in y.iter().enumerate() {
            g[[i, c]] -= 1.0;
        }
        g.mapv_inplace(|v| v / n as f32);
        let gw = x.t().dot(&g) + &(&model.w * o.weight_decay);
        let gb = g.sum_axis(Axis(0));
        let (c1, c2) = (1.0 - b1.powi(t as i32), 1.0 - b2.powi(t as i32));
        mw.zip_mut_with(&gw, |m, &g| *m = b1 * *m + (1.0 - b1) * g);
        vw.zip_mut_with(&gw, |v, &g| *v = b2 * *v + (1.0 - b2) * g * g);
        mb.zip_mut_with(&gb, |m, &g| *m = b1 * *m + (1.0 - b1) * g);
        vb.zip_mut_with(&gb, |v, &g| *v = b2 * *v + (1.0 - b2) * g * g);
        let lr = o.learning_rate;
        ndarray::Zip::from(&mut model.w)
            .and(&mw)
            .and(&vw)
            .for_each(|w, &m, &v| *w -= lr * (m / c1) / ((v / c2).sqrt() + eps));
        ndarray::Zip::from(&mut model.b)
            .and(&mb)
            .and(&vb)
            .for_each(|b, &m, &v| *b -= lr * (m / c1) / ((v / c2).sqrt() + eps));
    }
    model
}

impl Linear {
    /// Class scores (logits) of one embedding.
    pub fn scores(&self, e: &[f32]) -> Vec<f32> {
        let x = ndarray::ArrayView1::from(e);
        (x.dot(&self.w) + &self.b).to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_fixes_what_the_class_mean_start_cannot() {
        // Both classes have mean direction (1, 1)/√2, so the class-mean start ties
        // (loss ln 2); they are separable only through the bias (x + y = 1 vs ≤ 0.7).
        let pts = [([1.0f32, 0.0], 0), ([0.0, 1.0], 0), ([0.3, 0.3], 1), ([0.35, 0.35], 1)];
        let x = Array2::from_shape_fn((4, 2), |(i, j)| pts[i].0[j]);
        let y: Vec<usize> = pts.iter().map(|p| p.1).collect();
        let start = train(&x, &y, 2, &LinearOptions { iterations: 0, ..Default::default() });
        assert!((loss(&start, &x, &y) - std::f32::consts::LN_2).abs() < 1e-5);
        let trained = train(&x, &y, 2, &LinearOptions { iterations: 300, learning_rate: 0.05, ..Default::default() });
        assert!(loss(&trained, &x, &y) < 0.2, "{}", loss(&trained, &x, &y));
        for (p, c) in pts {
            let s = trained.scores(&p);
            assert_eq!(usize::from(s[1] > s[0]), c);
        }
    }
}
