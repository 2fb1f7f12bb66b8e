//! PNG bytes of a bitmap plotters drew: the one encoder of the report's and
//! the plan's PNG plots.

/// PNG bytes of an RGB8 bitmap of `size` (width, height) pixels, as plotters'
/// bitmap backend draws it.
pub(crate) fn encode_png(rgb: &[u8], size: (u32, u32)) -> anyhow::Result<Vec<u8>> {
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        rgb,
        size.0,
        size.1,
        image::ColorType::Rgb8,
    )
    .map_err(|e| anyhow::anyhow!("encoding the PNG: {e}"))?;
    Ok(png)
}
