//! Text of the PNG figures, laid out with ab_glyph directly.
//!
//! plotters' own ab_glyph text (0.3.7) places each glyph's bitmap at the pen position without the
//! glyph's left side bearing and truncates the pen to whole pixels, so spacing depends on the
//! letters ("qua drotor", "C1 _b ar"), and it puts the baseline at half the font size, so text sits
//! too high in its box. [`GlyphText`] wraps a backend and replaces its text drawing and measuring:
//! glyphs are outlined at their sub-pixel pen position (advance plus kerning), the box is the
//! font's ascent to descent, and the baseline is at the ascent. Everything else goes to the
//! wrapped backend unchanged.

use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};
use std::sync::OnceLock;

/// The embedded face every text of the PNG figures uses (the SVG figures name the family only).
fn face() -> &'static FontRef<'static> {
    static FACE: OnceLock<FontRef<'static>> = OnceLock::new();
    FACE.get_or_init(|| {
        FontRef::try_from_slice(super::style::FONT_TTF)
            .expect("the embedded DejaVuSans.ttf parses (checked by register_fonts)")
    })
}

/// Width and height (ascent to descent) of `text` at `size` px, px.
pub fn measure(text: &str, size: f64) -> (f64, f64) {
    let font = face().as_scaled(PxScale::from(size as f32));
    let mut width = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            width += font.kern(p, id);
        }
        width += font.h_advance(id);
        prev = Some(id);
    }
    (width as f64, (font.ascent() - font.descent()) as f64)
}

/// Rasterises `text` at `size` px with its box's top-left corner at (0, 0); calls `pixel` with
/// every covered pixel and its coverage in (0, 1].
pub fn rasterise(text: &str, size: f64, mut pixel: impl FnMut(i32, i32, f32)) {
    let font = face().as_scaled(PxScale::from(size as f32));
    let baseline = font.ascent();
    let mut pen = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            pen += font.kern(p, id);
        }
        let glyph = id.with_scale_and_position(font.scale(), point(pen, baseline));
        if let Some(outline) = font.outline_glyph(glyph) {
            let min = outline.px_bounds().min;
            outline.draw(|x, y, coverage| {
                if coverage > 0.0 {
                    pixel(min.x as i32 + x as i32, min.y as i32 + y as i32, coverage);
                }
            });
        }
        pen += font.h_advance(id);
        prev = Some(id);
    }
}

/// A backend whose text is laid out by this module (see the module documentation).
pub struct GlyphText<DB> {
    inner: DB,
    /// Whether text is rasterised here (bitmaps) or handed to the backend as text (SVG), measured
    /// here either way.
    raster: bool,
}

impl<DB> GlyphText<DB> {
    /// Wraps a bitmap backend: text is rasterised here.
    pub fn new(inner: DB) -> GlyphText<DB> {
        GlyphText {
            inner,
            raster: true,
        }
    }

    /// Wraps a vector backend: text stays text, measured with the metrics of the embedded font.
    pub fn vector(inner: DB) -> GlyphText<DB> {
        GlyphText {
            inner,
            raster: false,
        }
    }
}

impl<DB: DrawingBackend> DrawingBackend for GlyphText<DB> {
    type ErrorType = DB::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.inner.blit_bitmap(pos, size, src)
    }

    fn estimate_text_size<TStyle: BackendTextStyle>(
        &self,
        text: &str,
        style: &TStyle,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        let (w, h) = measure(text, style.size());
        Ok((w.ceil() as u32, h.ceil() as u32))
    }

    fn draw_text<TStyle: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        if !self.raster {
            return self.inner.draw_text(text, style, pos);
        }
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let (w, h) = measure(text, style.size());
        let (w, h) = (w.round() as i32, h.round() as i32);
        let anchor = style.anchor();
        let dx = match anchor.h_pos {
            HPos::Left => 0,
            HPos::Right => -w,
            HPos::Center => -w / 2,
        };
        let dy = match anchor.v_pos {
            VPos::Top => 0,
            VPos::Center => -h / 2,
            VPos::Bottom => -h,
        };
        let transform = style.transform();
        let (width, height) = self.get_size();
        let mut result = Ok(());
        rasterise(text, style.size(), |x, y, coverage| {
            if result.is_err() {
                return;
            }
            let (x, y) = transform.transform(x + dx, y + dy);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && y >= 0 && (x as u32) < width && (y as u32) < height {
                let c = BackendColor {
                    alpha: color.alpha * coverage as f64,
                    rgb: color.rgb,
                };
                result = self.inner.draw_pixel((x, y), c);
            }
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Columns (x) that hold ink when `text` is rasterised at 20 px.
    fn inked_columns(text: &str) -> Vec<i32> {
        let mut cols = std::collections::BTreeSet::new();
        rasterise(text, 20.0, |x, _, c| {
            if c > 0.3 {
                cols.insert(x);
            }
        });
        cols.into_iter().collect()
    }

    /// Widths of the blank gaps between inked columns.
    fn gaps(text: &str) -> Vec<i32> {
        inked_columns(text)
            .windows(2)
            .map(|w| w[1] - w[0] - 1)
            .filter(|&g| g > 0)
            .collect()
    }

    #[test]
    fn letters_of_a_word_are_evenly_spaced_with_no_gap_as_wide_as_a_space() {
        let (space, _) = measure(" ", 20.0);
        for word in ["quadrotor", "C1_bar", "formation", "attitude"] {
            let widest = gaps(word).into_iter().max().unwrap_or(0);
            assert!(
                (widest as f64) < space * 0.8,
                "{word}: a gap of {widest} px inside the word (a space is {space:.1} px)"
            );
        }
        // A real space is still a gap.
        assert!(gaps("qua drotor").into_iter().max().unwrap() as f64 >= space * 0.8);
    }

    #[test]
    fn the_text_box_holds_every_inked_pixel_of_the_text() {
        let text = "Γ̂ quadrotor (m/s²) gjpqy";
        let (w, h) = measure(text, 20.0);
        rasterise(text, 20.0, |x, y, _| {
            assert!(x >= -2 && (x as f64) <= w + 2.0, "x = {x} outside 0..{w}");
            assert!(y >= -2 && (y as f64) <= h + 2.0, "y = {y} outside 0..{h}");
        });
    }
}
