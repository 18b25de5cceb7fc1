//! Input checks shared by the loss modules.

use crate::image::check_dimensions;
use crate::{Error, Image, Result};

/// Checks that `img` is a well-formed, non-empty image; `what` names it in messages.
pub(crate) fn check_image<T>(what: &str, img: &Image<T>) -> Result<()> {
    check_dimensions(what, img.width, img.height)?;
    if img.channels == 0 {
        return Err(Error::input(what, "image has zero channels"));
    }
    let expected = img
        .width
        .checked_mul(img.height)
        .and_then(|p| p.checked_mul(img.channels));
    if expected != Some(img.data.len()) {
        return Err(Error::input(
            what,
            format!(
                "buffer has {} values, expected {}x{}x{}",
                img.data.len(),
                img.width,
                img.height,
                img.channels
            ),
        ));
    }
    Ok(())
}

/// Checks that both images are well formed and have the same width, height and channels.
pub(crate) fn check_same_shape<T>(
    a_name: &str,
    a: &Image<T>,
    b_name: &str,
    b: &Image<T>,
) -> Result<()> {
    check_image(a_name, a)?;
    check_image(b_name, b)?;
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        return Err(Error::input(
            format!("{a_name} / {b_name}"),
            format!(
                "shapes differ: {}x{}x{} vs {}x{}x{}",
                a.width, a.height, a.channels, b.width, b.height, b.channels
            ),
        ));
    }
    Ok(())
}
