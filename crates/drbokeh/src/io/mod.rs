//! Reading and writing: layer stacks (NPZ), images (PNG/JPEG/TIFF/EXR), depth maps
//! (PNG/EXR/NPY/NPZ) and rendered outputs. Every reader validates what it returns and
//! names the file in its errors; every writer writes to a temporary file beside the
//! target and renames it, so a failed write leaves no partial output.

mod depth;
mod files;
mod npz;
mod raster;

pub use depth::{read_disparity, DepthKind, DisparityOptions};
pub use files::write_atomic;
pub use npz::{read_stack, write_gradients, write_stack};
pub(crate) use raster::is_linear;
pub use raster::{
    read_grey, read_matte, read_npy_image, read_rgb, write_grey, write_output, BitDepth,
    OutputFormat,
};
