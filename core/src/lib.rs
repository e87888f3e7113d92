//! # xsurf-core
//!
//! The pure algorithms of xsurf, free of middleware and I/O so that they are tested and
//! benchmarked alone:
//!
//! - [`edge`]: sub-pixel laser-line detection per image row or column;
//! - [`triangulate`]: camera ray / laser plane intersection, placed in `table` by the C-arm pose;
//! - [`pose`]: `table -> carm` over time, interpolated at image stamps;
//! - [`mesh`]: the organized grid (samples x frames) and its triangulation and smoothing;
//! - [`synth`]: the synthetic scanner, which renders scans and knows the true surface;
//! - [`xray`]: the radiograph's grey levels, cropping and placement in `table`;
//! - [`register`]: the second camera's placement refined against the first camera's surface;
//! - [`merge`]: one surface of a scan from the cameras' grids (refine, fuse, mesh, stitch);
//! - [`eval`]: accuracy and coverage against that truth.
//!
//! ```
//! use xsurf_core::edge::{EdgeConfig, EdgeDetector, LaserLine};
//! use xsurf_core::image::{Encoding, Image};
//!
//! // A 32x16 image with a bright vertical line centred on column 12 (a line runs along at
//! // least `min_run` rows).
//! let mut img = Image::new(32, 16, Encoding::Mono8);
//! for (i, v) in img.data.iter_mut().enumerate() {
//!     let x = (i % 32) as f32;
//!     *v = (10.0 + 200.0 * (-((x - 12.0).powi(2)) / 4.5).exp()) as u8;
//! }
//! let mut detector = EdgeDetector::new(EdgeConfig::default()).unwrap();
//! let mut line = LaserLine::default();
//! detector.detect(&img.view().unwrap(), &mut line).unwrap();
//! assert!(line.u.iter().all(|u| (u - 12.0).abs() < 0.05));
//! ```
#![deny(missing_docs)]

pub mod calib;
pub mod camera;
mod cells;
pub mod edge;
pub mod eval;
pub mod fuse;
pub mod geom;
pub mod holes;
pub mod image;
pub mod limits;
pub mod merge;
pub mod mesh;
pub mod par;
pub mod pose;
pub mod register;
pub mod rig;
pub mod synth;
pub mod triangulate;
pub mod xray;
pub mod zipper;
