//! Clustered-ellipsoid and line levels of detail (Clasen, Paar, Prohaska 2010,
//! "Level of Detail for Trees using Clustered Ellipsoids").
//!
//! - [`leaves`]: every leaf → one ellipsoid (uniform surface samples, alpha-tested
//!   against the leaf texture, then PCA).
//! - [`hierarchy`]: levels of n/4, n/16, … 1 clusters, each the best of several EM
//!   starts (alg. 1), as ellipsoids by weighted PCA, sized and noise-calibrated by
//!   image error against the full mesh rendered by Sylva's own pipelines.
//! - [`lines`]: a line skeleton from the branch mesh, simplified by agglomerative
//!   straighten/combine merges chosen by image error (§3.2).

pub mod bake;
pub mod em;
pub mod hierarchy;
pub mod leaves;
pub mod lines;

pub use crate::rng::Rng;
