//! Scenes exported to other formats.

pub mod tiles3d;
