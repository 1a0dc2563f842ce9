//! The benchmark scenes: meshes, cameras and settings of each, by name.

use std::path::Path;

use super::SCENES;
use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::settings::{Dist, RasterSettings, Rgb};

/// A benchmark scene: what to render and how.
pub struct Scene {
    /// Its name in [`SCENES`]; a band's is `NAME[rows A..B]`.
    pub name: String,
    /// One line saying what it is (mesh, size, views, settings).
    pub description: String,
    /// The mesh.
    pub mesh: Mesh,
    /// One camera per view.
    pub cameras: Vec<Camera>,
    /// Lights.
    pub lighting: Lighting,
    /// Raster settings.
    pub settings: RasterSettings,
    /// For a band: the rows `[first, end)` of the full frame it renders.
    pub rows: Option<[u32; 2]>,
}

/// SoftRas's default camera distance, `1/tan 30° + 1`.
pub(super) const DISTANCE: f64 = 2.732;

pub(super) fn load(assets: &Path, file: &str, texture_res: u32) -> Result<Mesh> {
    Ok(Mesh::load_obj(&assets.join(file), texture_res)?)
}

impl Scene {
    /// Builds scene `name` from the meshes in `assets`.
    ///
    /// - `spot-256`, `blurry-256`: spot with R = 5 textures (as SoftRas's `demo_render.py`),
    ///   256², seen from distance 2.732, elevation 30°, azimuth 45° (the demo's σ/γ sweep view).
    /// - `sphere-64x120`: as SoftRas's `demo_deform.py` renders its template: the 1352-vertex
    ///   sphere scaled by 0.5, 64², viewing angle 15°, hard colour, σ = 1e-4, 120 views at
    ///   distance 2.732, elevation 30°, azimuths 0°, 3°, …, 357°.
    /// - `dense-1024`: the 1352-vertex sphere subdivided three times ([`Mesh::subdivided`]: 172 800
    ///   faces), 1024², the spot view.
    /// - `spot3-1024` ([`LARGE_SCENES`](super::LARGE_SCENES)): spot (R = 1) subdivided three times, 1024², the spot
    ///   view.
    /// - `blurry-1024` ([`LARGE_SCENES`](super::LARGE_SCENES)): `blurry-256` at 1024².
    /// - `crowded-327k`, `spread-327k` ([`LARGE_SCENES`](super::LARGE_SCENES)): an icosphere subdivided seven times
    ///   (327 680 faces), 64², σ 1e-5, the default camera: of radius 0.1 inside the tile of
    ///   pixels 16..24 (every face in that tile), or of radius 0.9 filling the frame.
    pub fn load(name: &str, assets: &Path) -> Result<Scene> {
        let spot_view = Camera::from_angles(DISTANCE, 30.0, 45.0);
        let spot_texture_res = 5;
        let base_settings = RasterSettings::default();
        Ok(match name {
            "spot-256" => Scene {
                name: "spot-256".into(),
                description: String::new(),
                mesh: load(assets, "spot_triangulated.obj", spot_texture_res)?,
                cameras: vec![spot_view],
                lighting: Lighting::default(),
                settings: RasterSettings {
                    width: 256,
                    height: 256,
                    sigma: 1e-5,
                    gamma: 1e-4,
                    ..base_settings
                },
                rows: None,
            },
            "sphere-64x120" => {
                let mut mesh = load(assets, "sphere_1352.obj", 1)?;
                for p in &mut mesh.positions {
                    *p = p.map(|c| c * 0.5);
                }
                let projection = Projection::Perspective {
                    viewing_angle_deg: 15.0,
                };
                Scene {
                    name: "sphere-64x120".into(),
                    description: String::new(),
                    mesh,
                    cameras: (0..120)
                        .map(|i| Camera {
                            projection,
                            ..Camera::from_angles(DISTANCE, 30.0, f64::from(3 * i))
                        })
                        .collect(),
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 64,
                        height: 64,
                        sigma: 1e-4,
                        rgb: Rgb::Hard,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            // Both subdivided three times (`Mesh::subdivided`), at 1024² from the spot view.
            "dense-1024" | "spot3-1024" => {
                let base = if name == "dense-1024" {
                    "sphere_1352.obj"
                } else {
                    "spot_triangulated.obj"
                };
                Scene {
                    name: name.into(),
                    description: String::new(),
                    mesh: load(assets, base, 1)?
                        .subdivided()?
                        .subdivided()?
                        .subdivided()?,
                    cameras: vec![spot_view],
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 1024,
                        height: 1024,
                        sigma: 1e-5,
                        gamma: 1e-4,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            "blurry-256" | "blurry-1024" => Scene {
                name: name.into(),
                description: String::new(),
                mesh: load(assets, "spot_triangulated.obj", spot_texture_res)?,
                cameras: vec![spot_view],
                lighting: Lighting::default(),
                settings: RasterSettings {
                    width: if name == "blurry-256" { 256 } else { 1024 },
                    height: if name == "blurry-256" { 256 } else { 1024 },
                    sigma: 3e-2,
                    gamma: 3e-1,
                    ..base_settings
                },
                rows: None,
            },
            "crowded-327k" | "spread-327k" => {
                let (radius, centre) = if name == "crowded-327k" {
                    (0.1, [-0.59, 0.59])
                } else {
                    (0.9, [0.0, 0.0])
                };
                let mut mesh = Mesh::icosphere(7);
                for p in &mut mesh.positions {
                    *p = [
                        radius * p[0] + centre[0],
                        radius * p[1] + centre[1],
                        radius * p[2],
                    ];
                }
                Scene {
                    name: name.into(),
                    description: String::new(),
                    mesh,
                    cameras: vec![Camera::default()],
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 64,
                        height: 64,
                        sigma: 1e-5,
                        gamma: 1e-4,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            _ => {
                return Err(Error::Input(format!(
                    "bench: unknown scene `{name}`; the scenes are {}",
                    SCENES.join(", ")
                )));
            }
        }
        .described())
    }

    /// The middle `rows` rows of this scene's frame as a scene of its own: the same faces over
    /// the same pixel centres, so every pixel visits the same faces as in the full frame.
    ///
    /// For an `N × N` frame the band is `N × rows` with `S = rows`, so pixel centres are the
    /// full frame's scaled by `k = N / rows`; screen space is scaled to match (perspective
    /// `tan a' = tan a / k`, orthographic `s' = k s`), and σ by `k²`, since euclidean coverage
    /// `sigmoid(δ d² / σ)` and its cut-off box are in screen units. Only f32 rounding differs.
    /// Needs a square frame, `N − rows` even, euclidean distance and no anti-aliasing.
    pub fn band(&self, rows: u32) -> Result<Scene> {
        let s = &self.settings;
        let n = s.height;
        if s.width != n
            || rows == 0
            || rows >= n
            || (n - rows) % 2 != 0
            || s.antialias
            || s.dist != Dist::Euclidean
        {
            return Err(Error::Input(format!(
                "bench: cannot take a {rows}-row band of {} ({}x{}, {:?} distance{}): a band \
                 needs a square frame, fewer rows than it, an even margin, euclidean distance \
                 and no anti-aliasing",
                self.name,
                s.width,
                s.height,
                s.dist,
                if s.antialias { ", anti-aliased" } else { "" },
            )));
        }
        let k = f64::from(n) / f64::from(rows);
        let cameras = self
            .cameras
            .iter()
            .map(|c| {
                let projection = match c.projection {
                    Projection::Perspective { viewing_angle_deg } => Projection::Perspective {
                        viewing_angle_deg: (viewing_angle_deg.to_radians().tan() / k)
                            .atan()
                            .to_degrees(),
                    },
                    Projection::Orthographic { scale } => {
                        Projection::Orthographic { scale: scale * k }
                    }
                    Projection::Matrix { .. } => {
                        return Err(Error::Input(
                            "bench: a band needs a perspective or orthographic camera".into(),
                        ));
                    }
                };
                Ok(Camera { projection, ..*c })
            })
            .collect::<Result<_>>()?;
        let first = (n - rows) / 2;
        Ok(Scene {
            name: format!("{}[rows {first}..{}]", self.name, first + rows),
            description: String::new(),
            mesh: self.mesh.clone(),
            cameras,
            lighting: self.lighting.clone(),
            settings: RasterSettings {
                height: rows,
                sigma: s.sigma * k * k,
                ..*s
            },
            rows: Some([first, first + rows]),
        }
        .described())
    }

    fn described(mut self) -> Self {
        let s = &self.settings;
        self.description = format!(
            "{}: {} faces (R = {}), {} view(s) of {}x{}, sigma {:e}, gamma {:e}, rgb {:?}{}",
            self.name,
            self.mesh.face_count(),
            self.mesh.texture_res,
            self.cameras.len(),
            s.width,
            s.height,
            s.sigma,
            s.gamma,
            s.rgb,
            match self.rows {
                Some([a, b]) => format!(
                    " (rows {a}..{b} of the {0}x{0} frame, screen space scaled to match)",
                    s.width
                ),
                None => String::new(),
            },
        );
        self
    }
}
