//! Reading and writing: layer stacks (NPZ), images (PNG/JPEG/TIFF/EXR), depth maps
//! (PNG/EXR/NPY/NPZ) and rendered outputs. Every reader validates what it returns and
//! names the file in its errors, and checks the size an input claims (from its header)
//! against the input budget ([`crate::budget`]) before reading its data. Every writer
//! writes to a temporary beside the target and renames it into place once complete
//! ([`Staging`], several outputs at once); [`OutputPlan`] checks output paths before any
//! work; [`temps`] removes temporaries on signals and sweeps those of killed runs.

mod depth;
mod encode;
mod files;
mod npy;
mod npz;
mod outputs;
mod raster;
mod staging;
pub mod temps;

pub use depth::{read_disparity, DepthKind, DisparityOptions};
pub use npz::{read_stack, write_gradients, write_stack};
pub use outputs::{DirMode, OutputPlan};
pub(crate) use raster::decode_as;
pub(crate) use raster::is_linear;
pub use raster::{
    image_dimensions, read_grey, read_matte, read_npy_image, read_rgb, write_grey, write_output,
    BitDepth, OutputFormat,
};
pub use staging::{write_atomic, Staging};
