//! The map's 95 % band, drawn as the union of its stretches.
//!
//! The band along a path is not a polygon egui can fill: egui fills convex
//! shapes only, and a band is neither convex nor simple where the path
//! turns tighter than the band is wide (its inner edge folds back) or
//! turns on the spot (a skid-steer robot: every stretch there is a fan
//! around one point). Drawn as translucent quads or triangles, each overlap
//! is blended once more, and such turns showed as white fans and seams. So
//! the stretches are rasterised into one coverage mask in screen pixels
//! (each pixel covered or not, whatever the number of stretches over it),
//! and the mask is drawn once, tinted with the band's colour. The mask is
//! made again only when the band or the view changes.

use std::hash::{Hash, Hasher};
use std::ops::RangeInclusive;

use egui::{Color32, ColorImage, Mesh, Pos2, Rect, Shape, TextureHandle, TextureOptions};
use egui_plot::{PlotBounds, PlotGeometry, PlotItem, PlotItemBase, PlotPoint, PlotTransform};

use super::SIGMA;

/// Mask samples per screen point along each axis: 2 x 2 samples per point,
/// averaged by the texture's linear filter, smooth the band's edges.
const SAMPLES_PER_POINT: f32 = 2.0;
/// Largest mask (samples): bounds the memory and the time of one rasterising.
const MAX_SAMPLES: usize = 4_000_000;

/// The band as a plot item: at each drawn point the path (east, north) and
/// the band's left and right edges there.
pub struct BandLayer {
    base: PlotItemBase,
    points: Vec<[[f64; 2]; 3]>,
}

impl BandLayer {
    pub fn new(points: Vec<[[f64; 2]; 3]>) -> Self {
        Self {
            base: PlotItemBase::new("95 % band".to_string()),
            points,
        }
    }

    /// A hash of what the mask depends on: the band and the view.
    fn key(&self, frame: Rect, bounds: &PlotBounds) -> u64 {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for v in self.points.iter().flatten().flatten() {
            v.to_bits().hash(&mut h);
        }
        for v in [frame.min.x, frame.min.y, frame.max.x, frame.max.y] {
            v.to_bits().hash(&mut h);
        }
        for v in [bounds.min(), bounds.max()].iter().flatten() {
            v.to_bits().hash(&mut h);
        }
        h.finish()
    }
}

/// The mask last drawn, kept between frames in egui's memory.
#[derive(Clone, Default)]
struct MaskCache {
    key: u64,
    texture: Option<TextureHandle>,
}

impl PlotItem for BandLayer {
    fn shapes(&self, ui: &egui::Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        let frame = *transform.frame();
        let scale = SAMPLES_PER_POINT
            .min((MAX_SAMPLES as f32 / frame.area().max(1.0)).sqrt())
            .max(0.25);
        let (w, h) = (
            (frame.width() * scale).ceil() as usize,
            (frame.height() * scale).ceil() as usize,
        );
        if w == 0 || h == 0 {
            return;
        }
        let key = self.key(frame, transform.bounds());
        let id = egui::Id::unique("gyropath-map-band-mask");
        let mut cache: MaskCache = ui.ctx().data(|d| d.get_temp(id)).unwrap_or_default();
        let texture = match cache.texture.clone() {
            Some(t) if cache.key == key => t,
            old => {
                let to_mask = |p: &[f64; 2]| {
                    let s = transform.position_from_point(&PlotPoint::new(p[0], p[1]));
                    [(s.x - frame.min.x) * scale, (s.y - frame.min.y) * scale]
                };
                let covered = coverage(&stretches(&self.points, to_mask), w, h);
                let image = ColorImage::new(
                    [w, h],
                    covered
                        .iter()
                        .map(|&c| if c { SIGMA } else { Color32::TRANSPARENT })
                        .collect(),
                );
                let texture = match old {
                    Some(mut t) => {
                        t.set(image, TextureOptions::LINEAR);
                        t
                    }
                    None => ui
                        .ctx()
                        .load_texture("map band", image, TextureOptions::LINEAR),
                };
                cache = MaskCache {
                    key,
                    texture: Some(texture.clone()),
                };
                ui.ctx().data_mut(|d| d.insert_temp(id, cache));
                texture
            }
        };
        let mut mesh = Mesh::with_texture(texture.id());
        mesh.add_rect_with_uv(
            frame,
            Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
            Color32::WHITE,
        );
        shapes.push(Shape::mesh(mesh));
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        SIGMA
    }

    fn allow_hover(&self) -> bool {
        false
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::None
    }

    fn bounds(&self) -> PlotBounds {
        let mut b = PlotBounds::NOTHING;
        for [x, y] in self.points.iter().flatten() {
            b.extend_with(&PlotPoint::new(*x, *y));
        }
        b
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

/// The triangles that cover the band between each two drawn points, in the
/// mask's coordinates: on each side of the path the stretch from the path
/// to that side's edge, `(c0, c1, e1)` and `(c0, e1, e0)`. Split at the path
/// this way, a turn on the spot (`c0 = c1`) is a fan of wedges around it.
fn stretches(
    points: &[[[f64; 2]; 3]],
    to_mask: impl Fn(&[f64; 2]) -> [f32; 2],
) -> Vec<[[f32; 2]; 3]> {
    let mapped: Vec<[[f32; 2]; 3]> = points
        .iter()
        .map(|[c, l, r]| [to_mask(c), to_mask(l), to_mask(r)])
        .collect();
    let mut tris = Vec::with_capacity(4 * mapped.len());
    for w in mapped.windows(2) {
        let ([c0, l0, r0], [c1, l1, r1]) = (w[0], w[1]);
        for (e0, e1) in [(l0, l1), (r0, r1)] {
            tris.push([c0, c1, e1]);
            tris.push([c0, e1, e0]);
        }
    }
    tris
}

/// Which samples of a `w` x `h` mask (sample centres at `i + 0.5`) lie in
/// at least one of the triangles, in either winding: a sample is inside
/// when the three edge functions `(b - a) x (p - a)` share a sign.
fn coverage(tris: &[[[f32; 2]; 3]], w: usize, h: usize) -> Vec<bool> {
    let mut mask = vec![false; w * h];
    let edge = |a: [f32; 2], b: [f32; 2], p: [f32; 2]| {
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
    };
    for &[a, b, c] in tris {
        if !(a.iter().chain(&b).chain(&c)).all(|v| v.is_finite()) {
            continue;
        }
        let lo = |i: usize| a[i].min(b[i]).min(c[i]);
        let hi = |i: usize| a[i].max(b[i]).max(c[i]);
        let (x0, x1) = (
            lo(0).floor().max(0.0) as usize,
            (hi(0).ceil().max(0.0) as usize).min(w),
        );
        let (y0, y1) = (
            lo(1).floor().max(0.0) as usize,
            (hi(1).ceil().max(0.0) as usize).min(h),
        );
        for y in y0..y1 {
            for x in x0..x1 {
                let p = [x as f32 + 0.5, y as f32 + 0.5];
                let (e0, e1, e2) = (edge(a, b, p), edge(b, c, p), edge(c, a, p));
                if (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0) || (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0) {
                    mask[y * w + x] = true;
                }
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(mask: &[bool]) -> usize {
        mask.iter().filter(|&&c| c).count()
    }

    #[test]
    fn a_triangle_covers_its_area_in_either_winding() {
        let t = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]];
        let ccw = coverage(&[t], 20, 20);
        let cw = coverage(&[[t[0], t[2], t[1]]], 20, 20);
        assert_eq!(ccw, cw);
        // 50 samples of area; the diagonal's samples are on the edge.
        assert!((45..=60).contains(&count(&ccw)), "{}", count(&ccw));
        // Degenerate, off-mask and non-finite triangles cover nothing.
        let none = [
            [[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]],
            [[-30.0, -30.0], [-20.0, -30.0], [-30.0, -20.0]],
            [[f32::NAN, 0.0], [10.0, 0.0], [0.0, 10.0]],
        ];
        assert!(count(&coverage(&none, 20, 20)) <= 9);
    }

    #[test]
    fn overlapping_stretches_are_covered_once_and_a_turn_on_the_spot_is_a_disc() {
        // A robot turning on the spot at (50, 50): the band's half width 20
        // sweeps round it in 10-degree steps. The union is a disc of
        // radius 20 (1257 samples); drawn stretch by stretch the centre was
        // covered 36 times over.
        let points: Vec<[[f64; 2]; 3]> = (0..=36)
            .map(|k| {
                let a = (k as f64 * 10.0).to_radians();
                let n = [a.cos(), a.sin()];
                [
                    [50.0, 50.0],
                    [50.0 + 20.0 * n[0], 50.0 + 20.0 * n[1]],
                    [50.0 - 20.0 * n[0], 50.0 - 20.0 * n[1]],
                ]
            })
            .collect();
        let tris = stretches(&points, |p| [p[0] as f32, p[1] as f32]);
        let mask = coverage(&tris, 100, 100);
        let area = count(&mask) as f64;
        // The 36-gon inscribed in the circle has 99.5 % of its area.
        assert!((1200.0..=1270.0).contains(&area), "{area}");
        assert!(mask[50 * 100 + 50] && mask[50 * 100 + 68] && !mask[50 * 100 + 72]);
    }

    #[test]
    fn a_straight_band_covers_its_rectangle() {
        let points: Vec<[[f64; 2]; 3]> = (0..=10)
            .map(|k| {
                let x = 10.0 + 8.0 * k as f64;
                [[x, 50.0], [x, 55.0], [x, 45.0]]
            })
            .collect();
        let mask = coverage(
            &stretches(&points, |p| [p[0] as f32, p[1] as f32]),
            100,
            100,
        );
        // 80 x 10 samples.
        assert!((790..=830).contains(&count(&mask)), "{}", count(&mask));
    }
}
