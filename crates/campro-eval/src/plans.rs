//! Optimised tract plans kept by input size.
//!
//! tract optimises a graph for one input shape, so a model fed many sizes (a photo folder,
//! a detector's pyramid) is planned once a size. Each plan holds its own packed weights and
//! scratch layout, a few megabytes: kept without a bound, `simulate --enhance` over 300
//! photos of distinct sizes grew to 537 MB. [`Plans`] keeps the most recently used few.

use std::sync::{Arc, Mutex};
use tract_onnx::prelude::TypedSimplePlan;

/// Plans kept per model: a video has one size a pyramid level, a photo folder a few;
/// beyond this the least recently used is dropped (and planned again if it comes back).
pub const KEPT: usize = 12;

/// A plan for one input.
pub type Plan = Arc<TypedSimplePlan>;

/// At most [`KEPT`] plans by key (an input's size), least recently used first.
pub struct Plans<K> {
    kept: Mutex<Vec<(K, Plan)>>,
}

impl<K> Default for Plans<K> {
    fn default() -> Self {
        Self { kept: Mutex::new(Vec::new()) }
    }
}

impl<K: Copy + PartialEq> Plans<K> {
    /// The plan for `key`, made by `make` on first use (outside the lock, so threads plan
    /// other sizes meanwhile) and kept; a hit becomes the most recently used.
    pub fn get_or_make<E>(&self, key: K, make: impl FnOnce() -> Result<Plan, E>) -> Result<Plan, E> {
        if let Some(p) = self.touch(key) {
            return Ok(p);
        }
        let plan = make()?;
        let mut kept = self.lock();
        if let Some(i) = kept.iter().position(|(k, _)| *k == key) {
            // Another thread planned it meanwhile: keep one.
            let (k, p) = kept.remove(i);
            kept.push((k, p.clone()));
            return Ok(p);
        }
        if kept.len() >= KEPT {
            kept.remove(0);
        }
        kept.push((key, plan.clone()));
        Ok(plan)
    }

    /// The keys kept, least recently used first.
    pub fn keys(&self) -> Vec<K> {
        self.lock().iter().map(|(k, _)| *k).collect()
    }

    fn touch(&self, key: K) -> Option<Plan> {
        let mut kept = self.lock();
        let i = kept.iter().position(|(k, _)| *k == key)?;
        let entry = kept.remove(i);
        let plan = entry.1.clone();
        kept.push(entry);
        Some(plan)
    }

    /// The list, also after a panic on another thread: it is only ever pushed to and
    /// removed from whole, so it is never half-changed.
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(K, Plan)>> {
        self.kept.lock().unwrap_or_else(|p| p.into_inner())
    }
}
