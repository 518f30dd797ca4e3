//! Animated GIFs of a run: the SVG frames, rasterised with resvg and
//! encoded with the `gif` crate, one at a time.

use anyhow::{Context, Result, anyhow};
use resvg::{tiny_skia, usvg};
use std::path::Path;
use std::sync::Arc;

/// Width of the animation, pixels (frames are scaled to it).
const WIDTH: u32 = 800;

/// Options for rasterising the project's SVG pictures: the system's fonts,
/// with `sans-serif` mapped to a family the system has (labels need a
/// font; without one, shapes are still drawn).
pub fn svg_options() -> usvg::Options<'static> {
    let mut opt = usvg::Options::default();
    let mut db = usvg::fontdb::Database::new();
    db.load_system_fonts();
    // `sans-serif` maps to Arial unless told otherwise: use a family the
    // system has.
    let families: Vec<String> = db
        .faces()
        .flat_map(|f| f.families.iter().map(|(n, _)| n.clone()))
        .collect();
    if let Some(f) = [
        "DejaVu Sans",
        "Liberation Sans",
        "Noto Sans",
        "Arial",
        "Helvetica",
    ]
    .into_iter()
    .find(|f| families.iter().any(|n| n == f))
    .map(str::to_string)
    .or_else(|| families.first().cloned())
    {
        db.set_sans_serif_family(f);
    }
    opt.fontdb = Arc::new(db);
    opt
}

/// Rasterise an SVG document at `width` pixels (height to scale) on white.
pub fn rasterise(svg: &str, width: u32, opt: &usvg::Options<'_>) -> Result<tiny_skia::Pixmap> {
    let tree = usvg::Tree::from_str(svg, opt)?;
    let size = tree.size();
    let scale = width as f32 / size.width().max(1.0);
    let (w, h) = (width, (size.height() * scale).ceil().max(1.0) as u32);
    let mut pixmap = tiny_skia::Pixmap::new(w, h).ok_or_else(|| anyhow!("{w}x{h} pixels"))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    Ok(pixmap)
}

/// A looping GIF written one frame at a time.
pub struct GifWriter {
    path: std::path::PathBuf,
    opt: usvg::Options<'static>,
    /// Hundredths of a second between frames (at least 2: viewers play
    /// faster ones flat out).
    delay: u16,
    file: Option<std::io::BufWriter<std::fs::File>>,
    encoder: Option<gif::Encoder<std::io::BufWriter<std::fs::File>>>,
    frames: usize,
}

impl GifWriter {
    /// A GIF at `path`, frames `delay_ms` apart.
    pub fn create(path: &Path, delay_ms: u32) -> Result<Self> {
        let opt = svg_options();
        let file =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(GifWriter {
            path: path.to_path_buf(),
            opt,
            delay: u16::try_from(delay_ms / 10).unwrap_or(u16::MAX).max(2),
            file: Some(std::io::BufWriter::new(file)),
            encoder: None,
            frames: 0,
        })
    }

    /// Add one frame (an SVG document), scaled to `WIDTH` pixels.
    pub fn push(&mut self, svg: &str) -> Result<()> {
        let k = self.frames;
        let pixmap = rasterise(svg, WIDTH, &self.opt).with_context(|| format!("frame {k}"))?;
        let (w, h) = (pixmap.width(), pixmap.height());
        let (w16, h16) = (
            u16::try_from(w).context("frame too wide")?,
            u16::try_from(h).context("frame too tall")?,
        );
        if self.encoder.is_none()
            && let Some(f) = self.file.take()
        {
            let mut e = gif::Encoder::new(f, w16, h16, &[])
                .with_context(|| format!("writing {}", self.path.display()))?;
            e.set_repeat(gif::Repeat::Infinite)?;
            self.encoder = Some(e);
        }
        let Some(e) = self.encoder.as_mut() else {
            return Ok(());
        };
        // Opaque (filled white first), so premultiplied RGBA is plain RGBA.
        let mut rgba = pixmap.take();
        let mut frame = gif::Frame::from_rgba_speed(w16, h16, &mut rgba, 10);
        frame.delay = self.delay;
        e.write_frame(&frame)
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.frames += 1;
        Ok(())
    }
}
