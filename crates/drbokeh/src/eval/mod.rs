//! Evaluation: every method on a ray-traced benchmark, scored against its ground truth and
//! written as a report; a refocus gallery for arbitrary photos; image-quality metrics.
//!
//! | module | job |
//! | --- | --- |
//! | `methods.rs` | the methods and how each renders ([`report::Method`]) |
//! | `scenes.rs` | loading benchmark scenes, the camera of a scene ([`report::SceneInputs`]) |
//! | `scoring.rs` | scores of a render and of a scene ([`report::SceneResult`]) |
//! | `run.rs` | running an evaluation ([`report::evaluate_benchmark`]) |
//! | `summary.rs` | buckets, aggregates, the report ([`report::Report`]) |
//! | `images.rs`, `tables.rs`, `plots.rs`, `html.rs` | pictures, CSV/Markdown, SVG, HTML |
//! | [`report`] | writes a report; gathers the above for callers |
//! | [`gallery`] | the refocus gallery |
//! | [`crate::baselines`] | classical renderers (shared with `dfd`) |
//! | [`metrics`] | PSNR, SSIM (matching scikit-image), MS-SSIM and error maps, on display-encoded images with data range 1 |

pub mod gallery;
mod html;
mod images;
mod methods;
pub mod metrics;
mod plots;
pub mod report;
mod run;
mod scenes;
mod scoring;
mod summary;
mod tables;
