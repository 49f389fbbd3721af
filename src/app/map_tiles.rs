//! The map's background: OpenStreetMap raster tiles (or another slippy-map
//! server's) under the GPS fixes and the path, so a user sees which street a
//! fix jumped off and where the receiver lost the sky.
//!
//! `walkers` (the best-kept egui map crate; 0.65 is on egui 0.37) does the
//! fetching on its own thread, the HTTP disk cache (honouring the server's
//! `Expires`/`Cache-Control`, as OpenStreetMap's tile policy asks), the
//! in-memory cache and the texture upload, and stands in a coarser tile while
//! a fine one loads. Its `Map` widget is not used: the map is an `egui_plot`
//! in the ride's local east/north metres, linked to the other plots, so this
//! file only picks the tiles the plot's view needs and draws them as a plot
//! item, each tile's corners placed exactly by `geodesy`. Offline, fetches
//! fail, nothing is drawn, and the map is the plain plot it was before.

use std::ops::RangeInclusive;
use std::path::PathBuf;

use egui::epaint::Vertex;
use egui::{Color32, Rect, Shape, TextureId};
use egui_plot::{PlotBounds, PlotGeometry, PlotItem, PlotItemBase, PlotPoint, PlotTransform};
use nalgebra::Vector3;
use walkers::sources::{Attribution, TileSource};
use walkers::{HeaderValue, HttpOptions, HttpTiles, Tile, TileId, Tiles};

use crate::geodesy::{Geodetic, LocalFrame, TilePosition, tile_zoom_for};

/// A slippy-map tile server and the folder its tiles are cached in.
#[derive(Clone, Debug, PartialEq)]
pub struct TileServer {
    /// The tile URL with `{z}`, `{x}` and `{y}` in it.
    pub url: String,
    /// HTTP cache folder; `None` keeps tiles in memory only.
    pub cache: Option<PathBuf>,
}

impl TileServer {
    /// OpenStreetMap's standard tiles.
    pub const OPENSTREETMAP: &str = "https://tile.openstreetmap.org/{z}/{x}/{y}.png";

    /// OpenStreetMap's tiles, or the server in `GYROPATH_TILE_URL` (a mirror,
    /// a local tile server for offline use), cached in the app's data folder
    /// (`~/.local/share/gyropath/tiles` on Linux).
    pub fn from_env() -> Self {
        Self {
            url: std::env::var("GYROPATH_TILE_URL")
                .ok()
                .filter(|u| !u.trim().is_empty())
                .unwrap_or_else(|| Self::OPENSTREETMAP.to_string()),
            cache: eframe::storage_dir("gyropath").map(|d| d.join("tiles")),
        }
    }

    /// The URL of one tile.
    pub fn tile_url(&self, zoom: u8, x: u32, y: u32) -> String {
        self.url
            .replace("{z}", &zoom.to_string())
            .replace("{x}", &x.to_string())
            .replace("{y}", &y.to_string())
    }
}

/// `walkers`' view of a [`TileServer`].
struct Source(TileServer);

impl TileSource for Source {
    fn tile_url(&self, id: TileId) -> String {
        self.0.tile_url(id.zoom, id.x, id.y)
    }

    fn attribution(&self) -> Attribution {
        ATTRIBUTION
    }
}

/// What OpenStreetMap's licence asks to be shown with its tiles.
const ATTRIBUTION: Attribution = Attribution {
    text: "© OpenStreetMap contributors",
    url: "https://www.openstreetmap.org/copyright",
    logo_light: None,
    logo_dark: None,
};

/// Tiles a view may ask for; a wider view takes a coarser zoom.
const MAX_TILES: usize = 48;
/// OpenStreetMap's finest zoom.
const MAX_ZOOM: u8 = 19;
/// Pixels across a tile.
const TILE_PX: f64 = 256.0;

/// What the background shows, for the attribution corner.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// Some tiles are drawn.
    Shown,
    /// Tiles are on their way.
    Loading,
    /// None could be fetched (offline, or the server refused).
    Unavailable,
}

/// The map background's runtime state: the server and its tile cache.
pub struct MapBackground {
    server: TileServer,
    /// Made at the first draw (it needs the egui context to upload textures).
    tiles: Option<HttpTiles>,
    status: Status,
}

impl MapBackground {
    pub fn new(server: TileServer) -> Self {
        Self {
            server,
            tiles: None,
            status: Status::Loading,
        }
    }

    pub fn status(&self) -> Status {
        self.status
    }

    /// The tiles under the plot's view, as a plot item to add before the
    /// data (items draw in order, so the map stays underneath).
    pub fn layer(
        &mut self,
        ctx: &egui::Context,
        transform: &PlotTransform,
        frame: &LocalFrame,
    ) -> TileLayer {
        let tiles = self.tiles.get_or_insert_with(|| {
            let options = HttpOptions {
                cache: self.server.cache.clone(),
                // OpenStreetMap's tile policy: say who is asking.
                user_agent: Some(HeaderValue::from_static(concat!(
                    "gyropath/",
                    env!("CARGO_PKG_VERSION"),
                    " (path reconstruction from gyro, odometer and GPS)"
                ))),
                ..HttpOptions::default()
            };
            HttpTiles::with_options(Source(self.server.clone()), options, ctx.clone())
        });
        let view = TileView::of(transform, frame, ctx.pixels_per_point());
        let mut quads = Vec::new();
        if let Some(view) = &view {
            for id in view.ids() {
                let Some(piece) = tiles.at(id) else {
                    continue;
                };
                // Raster is the only kind without walkers' `vector` feature;
                // the `if let` keeps this compiling should it ever be on.
                #[allow(irrefutable_let_patterns)]
                if let Tile::Raster(texture) = &piece.tile {
                    quads.push(Quad {
                        texture: texture.id(),
                        corners: tile_corners(id, frame),
                        uv: piece.uv,
                    });
                }
            }
        }
        self.status = if !quads.is_empty() {
            Status::Shown
        } else if tiles.stats().in_progress > 0 || view.is_none() {
            Status::Loading
        } else {
            Status::Unavailable
        };
        let tint = if ctx.global_style().visuals.dark_mode {
            // Dimmed, so the fixes and the path stay the brightest things on the map.
            Color32::from_gray(120)
        } else {
            Color32::from_gray(235)
        };
        TileLayer {
            base: PlotItemBase::new(String::new()),
            quads,
            tint,
        }
    }
}

/// The tiles a plot view needs: a zoom and a range of tile numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileView {
    pub zoom: u8,
    pub x: (u32, u32),
    pub y: (u32, u32),
}

impl TileView {
    /// The tiles covering `transform`'s bounds (metres east/north of
    /// `frame`'s origin), at the zoom whose pixels are about the screen's,
    /// coarser if that would take more than [`MAX_TILES`]; `None` for a
    /// degenerate view.
    pub fn of(
        transform: &PlotTransform,
        frame: &LocalFrame,
        pixels_per_point: f32,
    ) -> Option<Self> {
        let b = transform.bounds();
        let screen = transform.frame();
        let px = f64::from(screen.width() * pixels_per_point);
        if !(b.width() > 0.0 && b.height() > 0.0 && px >= 1.0 && b.is_finite()) {
            return None;
        }
        let centre = frame.to_geodetic(&Vector3::new(
            0.5 * (b.min()[0] + b.max()[0]),
            0.5 * (b.min()[1] + b.max()[1]),
            0.0,
        ));
        let corners = [
            (b.min()[0], b.min()[1]),
            (b.min()[0], b.max()[1]),
            (b.max()[0], b.min()[1]),
            (b.max()[0], b.max()[1]),
        ]
        .map(|(e, n)| frame.to_geodetic(&Vector3::new(e, n, 0.0)));
        let mut zoom = tile_zoom_for(b.width() / px, centre.lat_deg, TILE_PX, MAX_ZOOM);
        loop {
            let view = Self::covering(&corners, zoom);
            if view.count() <= MAX_TILES || zoom == 0 {
                return Some(view);
            }
            zoom -= 1;
        }
    }

    /// The tile range holding all of `corners` at `zoom`.
    fn covering(corners: &[Geodetic; 4], zoom: u8) -> Self {
        let last = (1u32 << zoom) - 1;
        let at = corners.map(|g| TilePosition::of(&g, zoom));
        let range = |v: [f64; 4]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let clamp = |t: f64| (t.floor().max(0.0) as u32).min(last);
            (clamp(lo), clamp(hi))
        };
        Self {
            zoom,
            x: range(at.map(|p| p.x)),
            y: range(at.map(|p| p.y)),
        }
    }

    pub fn count(&self) -> usize {
        (self.x.1 - self.x.0 + 1) as usize * (self.y.1 - self.y.0 + 1) as usize
    }

    fn ids(&self) -> impl Iterator<Item = TileId> + '_ {
        (self.y.0..=self.y.1).flat_map(move |y| {
            (self.x.0..=self.x.1).map(move |x| TileId {
                x,
                y,
                zoom: self.zoom,
            })
        })
    }
}

/// A tile's north-west, north-east, south-east and south-west corners in
/// metres east/north of `frame`'s origin. Drawn from its own corners, a tile
/// meets its neighbours without seams whatever the frame's distortion.
fn tile_corners(id: TileId, frame: &LocalFrame) -> [[f64; 2]; 4] {
    let (x, y) = (f64::from(id.x), f64::from(id.y));
    [(x, y), (x + 1.0, y), (x + 1.0, y + 1.0), (x, y + 1.0)].map(|(x, y)| {
        let g = TilePosition {
            x,
            y,
            zoom: id.zoom,
        }
        .geodetic();
        let enu = frame.to_enu(&Geodetic::new(g.lat_deg, g.lon_deg, frame.origin().alt_m));
        [enu.x, enu.y]
    })
}

/// One tile (or the part of a coarser one standing in for it) on the map.
struct Quad {
    texture: TextureId,
    corners: [[f64; 2]; 4],
    uv: Rect,
}

/// The tiles as a plot item. Its bounds are empty, so the map's automatic
/// zoom still fits the ride, not the tiles around it.
pub struct TileLayer {
    base: PlotItemBase,
    quads: Vec<Quad>,
    tint: Color32,
}

impl PlotItem for TileLayer {
    fn shapes(&self, _ui: &egui::Ui, transform: &PlotTransform, shapes: &mut Vec<Shape>) {
        for q in &self.quads {
            let mut mesh = egui::Mesh::with_texture(q.texture);
            let uv = [
                q.uv.left_top(),
                q.uv.right_top(),
                q.uv.right_bottom(),
                q.uv.left_bottom(),
            ];
            for (c, uv) in q.corners.iter().zip(uv) {
                mesh.vertices.push(Vertex {
                    pos: transform.position_from_point(&PlotPoint::new(c[0], c[1])),
                    uv,
                    color: self.tint,
                });
            }
            mesh.add_triangle(0, 1, 2);
            mesh.add_triangle(0, 2, 3);
            shapes.push(Shape::mesh(mesh));
        }
    }

    fn initialize(&mut self, _x_range: RangeInclusive<f64>) {}

    fn color(&self) -> Color32 {
        Color32::TRANSPARENT
    }

    fn allow_hover(&self) -> bool {
        false
    }

    fn geometry(&self) -> PlotGeometry<'_> {
        PlotGeometry::None
    }

    fn bounds(&self) -> PlotBounds {
        PlotBounds::NOTHING
    }

    fn base(&self) -> &PlotItemBase {
        &self.base
    }

    fn base_mut(&mut self) -> &mut PlotItemBase {
        &mut self.base
    }
}

/// The attribution in the map's lower right corner (a link to the licence),
/// or, when no tile could be fetched, a quiet note saying so.
pub fn attribution_ui(ui: &egui::Ui, transform: &PlotTransform, status: Status) {
    let frame = *transform.frame();
    let (text, link) = match status {
        Status::Shown => (ATTRIBUTION.text, true),
        Status::Loading => return,
        Status::Unavailable => ("map tiles unavailable (offline?)", false),
    };
    let painter = ui.painter_at(frame);
    let colour = ui.visuals().weak_text_color();
    let galley = painter.layout_no_wrap(text.to_string(), egui::FontId::proportional(10.0), colour);
    let rect = Rect::from_min_size(
        frame.right_bottom() - galley.size() - egui::vec2(6.0, 4.0),
        galley.size(),
    )
    .expand(2.0);
    painter.rect_filled(rect, 2.0, ui.visuals().extreme_bg_color.gamma_multiply(0.8));
    painter.galley(rect.min + egui::vec2(2.0, 2.0), galley, colour);
    if link {
        let response = ui
            .interact(
                rect,
                ui.scope_id().with("map-attribution"),
                egui::Sense::click(),
            )
            .on_hover_cursor(egui::CursorIcon::PointingHand)
            .on_hover_text(ATTRIBUTION.url);
        if response.clicked() {
            ui.ctx().open_url(egui::OpenUrl::new_tab(ATTRIBUTION.url));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transform(frame_px: f32, min: [f64; 2], max: [f64; 2]) -> PlotTransform {
        PlotTransform::new(
            Rect::from_min_size(egui::pos2(0.0, 0.0), egui::vec2(frame_px, frame_px)),
            PlotBounds::from_min_max(min, max),
            egui::Vec2b::new(false, false),
        )
    }

    #[test]
    fn a_view_takes_the_zoom_of_its_pixels_and_the_tiles_around_it() {
        let frame = LocalFrame::new(Geodetic::new(47.5, 19.0, 120.0));
        // 600 m over 600 px: 1 m per pixel, zoom round(16.69) = 17.
        let t = transform(600.0, [-300.0, -300.0], [300.0, 300.0]);
        let view = TileView::of(&t, &frame, 1.0).expect("view");
        assert_eq!(view.zoom, 17);
        // A zoom-17 tile is 203 m across here: 3-4 tiles each way.
        assert!((9..=16).contains(&view.count()), "{view:?}");
        // The origin's own tile is among them.
        let o = TilePosition::of(&frame.origin(), 17);
        assert!((view.x.0..=view.x.1).contains(&(o.x as u32)));
        assert!((view.y.0..=view.y.1).contains(&(o.y as u32)));
        // A view 200 km across on the same screen needs a coarser zoom, few tiles.
        let wide = transform(600.0, [-1e5, -1e5], [1e5, 1e5]);
        let view = TileView::of(&wide, &frame, 1.0).expect("view");
        assert!(view.zoom < 10 && view.count() <= MAX_TILES, "{view:?}");
        // A plot with no width on screen asks for nothing.
        let hidden = transform(0.0, [-300.0, -300.0], [300.0, 300.0]);
        assert!(TileView::of(&hidden, &frame, 1.0).is_none());
    }

    #[test]
    fn tiles_meet_without_seams() {
        let frame = LocalFrame::new(Geodetic::new(47.5, 19.0, 120.0));
        let o = TilePosition::of(&frame.origin(), 16);
        let (x, y) = (o.x as u32, o.y as u32);
        let a = tile_corners(TileId { x, y, zoom: 16 }, &frame);
        let east = tile_corners(
            TileId {
                x: x + 1,
                y,
                zoom: 16,
            },
            &frame,
        );
        let south = tile_corners(
            TileId {
                x,
                y: y + 1,
                zoom: 16,
            },
            &frame,
        );
        let close = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]) < 1e-6;
        assert!(close(a[1], east[0]) && close(a[2], east[3]));
        assert!(close(a[3], south[0]) && close(a[2], south[1]));
        // North up, east right, about 414 m a side at 47.5 deg, zoom 16.
        assert!(a[0][1] > a[3][1] && a[1][0] > a[0][0]);
        let side = a[1][0] - a[0][0];
        assert!((side - 413.9).abs() < 1.0, "{side}");
    }

    #[test]
    fn tile_urls_fill_the_template() {
        let s = TileServer {
            url: "http://127.0.0.1:8080/{z}/{x}/{y}.png".into(),
            cache: None,
        };
        assert_eq!(s.tile_url(3, 4, 5), "http://127.0.0.1:8080/3/4/5.png");
    }
}
