//! Recipes for vehicles: airplanes (airliner, fighter, propeller plane, biplane) and cars
//! (sedan, van, pickup, sports car, hatchback).

use glam::DVec3;

use super::builder::{Builder, THIN, hexahedron, sheared_box, style, v};

pub(super) fn airplane(b: &mut Builder) {
    match style(b, 4) {
        0 => airliner(b),
        1 => fighter(b),
        2 => propeller_plane(b),
        _ => biplane(b),
    }
}

fn airliner(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.5) { body } else { b.color() };
    let len = b.u(0.7, 1.0);
    let r = b.u(0.04, 0.085);
    let z0 = -len / 2.0;
    let nose = b.u(0.08, 0.15);
    let tail = b.u(0.12, 0.22);
    // Fuselage along z, nose at −z.
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, -z0 - tail), r, r, body);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, z0), r, r * 0.25, body);
    b.frustum(
        v(0.0, 0.0, -z0 - tail),
        v(0.0, r * 0.5, -z0),
        r,
        r * 0.3,
        body,
    );
    // Wings: swept, tapered slabs from the fuselage's axis outwards.
    let span = b.u(0.3, 0.55);
    let chord = b.u(0.15, 0.32);
    let taper = b.u(0.25, 0.75);
    let sweep = b.u(0.0, 0.3);
    let wz = b.u(-0.12, 0.05);
    let wt = THIN;
    let wy = b.u(-r * 0.6, r * 0.3);
    let dihedral = b.u(0.0, 0.06);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, wz, wy, span, chord, taper, sweep, dihedral, wt)),
            wing_color,
        );
    }
    // Tail plane and fin.
    let tspan = span * b.u(0.3, 0.45);
    let tchord = chord * b.u(0.45, 0.7);
    let tz = -z0 - tchord * 1.1;
    let fin_h = b.u(0.12, 0.22);
    // A T-tail sits on top of the fin, swept back with it.
    let t_tail = b.chance(0.3);
    let (ty, tsweep) = if t_tail {
        (r + fin_h - wt / 2.0, fin_h * 0.3)
    } else {
        (r * 0.3, 0.0)
    };
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, tz + tsweep, ty, tspan, tchord, 0.6, 0.06, 0.0, wt)),
            wing_color,
        );
    }
    let fc = tchord * 1.1;
    let fin = sheared_box(
        v(-wt / 2.0, 0.0, tz - fc * 0.2),
        v(wt / 2.0, r + fin_h, tz + fc * 0.8),
        v(0.0, 0.0, fc * 0.35),
        [1.0, (wt / fc).max(0.55)],
    );
    b.push(hexahedron(fin), wing_color);
    // No engines, two, or four under the wings.
    let engines: &[f64] = match style(b, 3) {
        0 => &[],
        1 => &[0.45],
        _ => &[0.33, 0.66],
    };
    let er = b.u(0.03, 0.05);
    let el = b.u(0.12, 0.2);
    for &at in engines {
        for sx in [-1.0, 1.0] {
            let x = sx * span * at;
            let z = wz + sweep * at - el * 0.4;
            b.frustum(
                v(x, wy - er * 1.2, z),
                v(x, wy - er * 1.2, z + el),
                er,
                er * 0.85,
                body,
            );
        }
    }
}

/// A wing on side `sx` (±1): root at x = 0 from z = `z` over `chord`, tip at x = `sx span`,
/// swept back by `sweep`, tapered to `taper × chord`, raised by `dihedral`. The tip is `t`
/// thick (at least [`THIN`]: the wing's thinnest spot) and the root thicker by the taper (up to
/// 1.25 t); the tip's chord is at least `t` too, measured square to the swept leading and
/// trailing edges (a delta's tip is a sliver otherwise).
#[allow(clippy::too_many_arguments)]
fn wing(
    sx: f64,
    z: f64,
    y: f64,
    span: f64,
    chord: f64,
    taper: f64,
    sweep: f64,
    dihedral: f64,
    t: f64,
) -> [DVec3; 8] {
    // An edge swept by dz over the span meets the tip at cos φ = 1 / sec: the tip's chord
    // square to it is the chord over sec. The trailing edge's sweep grows with the chord, so
    // a few passes settle it.
    let sec = |dz: f64| (1.0 + (dz / span).powi(2)).sqrt();
    let mut tip_chord = (chord * taper).max(t);
    for _ in 0..8 {
        tip_chord = tip_chord.max(t * sec(sweep).max(sec(sweep + tip_chord - chord)));
    }
    std::array::from_fn(|i| {
        let tip = (i & 1 != 0) == (sx > 0.0);
        let top = i & 2 != 0;
        let back = i & 4 != 0;
        let (x, zs, c, yy) = if tip {
            (sx * span, z + sweep, tip_chord, y + dihedral)
        } else {
            (0.0, z, chord, y)
        };
        let thick = if tip { t } else { t / taper.clamp(0.8, 1.0) };
        v(
            x,
            yy + if top { thick / 2.0 } else { -thick / 2.0 },
            zs + if back { c } else { 0.0 },
        )
    })
}

/// Fighter: a short, thick fuselage, delta wings, one or two fins.
fn fighter(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.6) { body } else { b.color() };
    let len = b.u(0.8, 1.0);
    let r = b.u(0.06, 0.09);
    let z0 = -len / 2.0;
    let nose = b.u(0.15, 0.25);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, -z0), r, r * 0.8, body);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, z0), r, r * 0.15, body);
    let span = b.u(0.22, 0.34);
    let chord = b.u(0.35, 0.5);
    let wz = -z0 - chord - b.u(0.02, 0.1);
    let taper = b.u(0.08, 0.25);
    let sweep = chord * (1.0 - taper) * b.u(0.8, 1.0);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, wz, 0.0, span, chord, taper, sweep, 0.0, THIN)),
            wing_color,
        );
    }
    let fin_h = b.u(0.12, 0.2);
    let fc = b.u(0.12, 0.2);
    let twin = b.chance(0.5);
    let xs: &[f64] = if twin { &[-1.0, 1.0] } else { &[0.0] };
    for &sx in xs {
        let x = sx * r * 0.7;
        let fin = sheared_box(
            v(x - THIN / 2.0, 0.0, -z0 - fc),
            v(x + THIN / 2.0, r + fin_h, -z0),
            v(sx * 0.03, 0.0, fc * 0.4),
            [1.0, (THIN / fc).max(0.5)],
        );
        b.push(hexahedron(fin), wing_color);
    }
}

/// A propeller disc (a dark, thin cylinder of radius drawn from `radius`) just in front of the
/// nose at `z0`.
fn propeller(b: &mut Builder, z0: f64, radius: (f64, f64)) {
    let prop = b.u(radius.0, radius.1);
    let prop_color = b.dark().map(|c| c * 2.0);
    b.frustum(
        v(0.0, 0.0, z0 - 0.005),
        v(0.0, 0.0, z0 - 0.005 - THIN),
        prop,
        prop,
        prop_color,
    );
}

/// The tail of a light plane: a small tapered tail plane at the fuselage's end and a swept
/// fin on top (heights and sweep in units of the fuselage radius and the tail chord).
struct LightTail {
    /// The tail plane's height, × r.
    plane_y: f64,
    /// The fin's height above the fuselage is drawn from this range.
    fin_height: (f64, f64),
    /// The fin's base height, × r.
    fin_base: f64,
    /// How far the fin's top is swept back, × the tail chord.
    fin_sweep: f64,
}

impl LightTail {
    /// The tail of a fuselage of radius `r` ending at `-z0`, behind wings of `span` and
    /// `chord`.
    fn build(&self, b: &mut Builder, z0: f64, r: f64, span: f64, chord: f64, color: [f32; 3]) {
        let tspan = span * b.u(0.3, 0.4);
        let tchord = chord * b.u(0.7, 1.0);
        let tz = -z0 - tchord;
        for sx in [-1.0f64, 1.0] {
            b.push(
                hexahedron(wing(
                    sx,
                    tz,
                    r * self.plane_y,
                    tspan,
                    tchord,
                    0.8,
                    0.02,
                    0.0,
                    THIN,
                )),
                color,
            );
        }
        let fin_h = b.u(self.fin_height.0, self.fin_height.1);
        let fin = sheared_box(
            v(-THIN / 2.0, r * self.fin_base, tz),
            v(THIN / 2.0, r + fin_h, -z0),
            v(0.0, 0.0, tchord * self.fin_sweep),
            [1.0, (THIN / tchord).max(0.6)],
        );
        b.push(hexahedron(fin), color);
    }
}

/// Propeller plane: straight, untapered wings on top of the fuselage, a propeller disc.
fn propeller_plane(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.5) { body } else { b.color() };
    let len = b.u(0.6, 0.8);
    let r = b.u(0.05, 0.08);
    let z0 = -len / 2.0;
    b.frustum(
        v(0.0, 0.0, z0 + 0.05),
        v(0.0, r * 0.4, -z0),
        r,
        r * 0.35,
        body,
    );
    b.frustum(v(0.0, 0.0, z0 + 0.07), v(0.0, 0.0, z0), r, r * 0.6, body);
    propeller(b, z0, (0.1, 0.16));
    let span = b.u(0.45, 0.55);
    let chord = b.u(0.1, 0.16);
    let wz = z0 + len * b.u(0.2, 0.35);
    let high = b.chance(0.6);
    let wy = if high { r * 0.9 } else { -r * 0.5 };
    let taper = b.u(0.75, 1.0);
    let dihedral = b.u(0.0, 0.03);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, wz, wy, span, chord, taper, 0.0, dihedral, THIN)),
            wing_color,
        );
    }
    let tail = LightTail {
        plane_y: 0.4,
        fin_height: (0.1, 0.16),
        fin_base: 0.3,
        fin_sweep: 0.4,
    };
    tail.build(b, z0, r, span, chord, wing_color);
}

/// Biplane: a short fuselage, two straight wings one above the other joined by struts near
/// their tips, a tail plane, a fin and a propeller disc.
fn biplane(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.4) { body } else { b.color() };
    let len = b.u(0.55, 0.75);
    let r = b.u(0.05, 0.08);
    let z0 = -len / 2.0;
    b.frustum(
        v(0.0, 0.0, z0 + 0.08),
        v(0.0, r * 0.3, -z0),
        r,
        r * 0.3,
        body,
    );
    b.frustum(v(0.0, 0.0, z0 + 0.08), v(0.0, 0.0, z0), r, r * 0.7, body);
    propeller(b, z0, (0.09, 0.15));
    let span = b.u(0.35, 0.5);
    let chord = b.u(0.1, 0.16);
    let gap = b.u(0.12, 0.22);
    let wz = z0 + len * b.u(0.12, 0.25);
    let lower = -r * 0.6;
    let stagger = b.u(-0.03, 0.05);
    let upper_span = span * b.u(1.0, 1.15);
    for (y, z, sp) in [(lower, wz, span), (lower + gap, wz - stagger, upper_span)] {
        for sx in [-1.0f64, 1.0] {
            b.push(
                hexahedron(wing(sx, z, y, sp, chord, 1.0, 0.0, 0.0, THIN)),
                wing_color,
            );
        }
    }
    let strut = THIN / 2.0;
    for sx in [-1.0, 1.0] {
        let x = sx * span * 0.75;
        let z = wz + chord * 0.5;
        b.frustum(
            v(x, lower, z),
            v(x, lower + gap, z - stagger),
            strut,
            strut,
            wing_color,
        );
    }
    let tail = LightTail {
        plane_y: 0.3,
        fin_height: (0.08, 0.14),
        fin_base: 0.2,
        fin_sweep: 0.3,
    };
    tail.build(b, z0, r, span, chord, wing_color);
}

pub(super) fn car(b: &mut Builder) {
    match style(b, 5) {
        0 => sedan(b),
        1 => van(b),
        2 => pickup(b),
        3 => sports_car(b),
        _ => hatchback(b),
    }
}

/// Hatchback: short, a cabin from the windscreen to the tail whose back slopes down.
fn hatchback(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.7, 0.9) / 2.0;
    let w = b.u(0.38, 0.48) / 2.0;
    let wr = b.u(0.07, 0.1);
    let body_h = b.u(0.12, 0.2);
    let y0 = wr * 0.7;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let front = b.u(0.3, 0.55) * l;
    let cab_h = b.u(0.12, 0.2);
    let back = l - b.u(0.0, 0.05);
    let slope = b.u(0.55, 0.85);
    let cab_len = back - (-l + front);
    // The roof ends short of the tail: the cabin's top is narrower along z and shifted forward.
    let cabin = sheared_box(
        v(-w * 0.93, y0 + body_h - 0.01, -l + front),
        v(w * 0.93, y0 + body_h + cab_h, back),
        v(0.0, 0.0, -cab_len * (1.0 - slope) / 2.0 + b.u(0.0, 0.04)),
        [b.u(0.85, 0.97), slope],
    );
    b.push(hexahedron(cabin), glass);
    let ww = b.u(THIN, 0.09);
    let wz = l * b.u(0.55, 0.72);
    wheels(b, w, wr, ww, [-wz, wz], tyre);
}

fn sedan(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.8, 1.0) / 2.0;
    let w = b.u(0.34, 0.48) / 2.0;
    let wr = b.u(0.06, 0.1);
    let body_h = b.u(0.1, 0.2);
    let y0 = wr * 0.7;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let cab_l = b.u(0.45, 0.65) * l;
    let cab_h = b.u(0.1, 0.17);
    let cab_z = b.u(-0.1, 0.15) * l;
    let cabin = sheared_box(
        v(-w * 0.92, y0 + body_h - 0.01, cab_z - cab_l),
        v(w * 0.92, y0 + body_h + cab_h, cab_z + cab_l),
        v(0.0, 0.0, b.u(0.0, 0.05)),
        [b.u(0.8, 0.95), b.u(0.55, 0.8)],
    );
    b.push(hexahedron(cabin), glass);
    let ww = b.u(THIN, 0.1);
    let wz = l * b.u(0.6, 0.75);
    for sx in [-1.0, 1.0] {
        for sz in [-1.0, 1.0] {
            let x = sx * (w - ww * 0.3);
            b.frustum(
                v(x - ww / 2.0, wr, sz * wz),
                v(x + ww / 2.0, wr, sz * wz),
                wr,
                wr,
                tyre,
            );
        }
    }
}

/// Van or SUV: a tall body and a long, tall cabin.
fn van(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.8, 1.0) / 2.0;
    let w = b.u(0.4, 0.5) / 2.0;
    let wr = b.u(0.07, 0.11);
    let body_h = b.u(0.16, 0.26);
    let y0 = wr * 0.7;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let front = b.u(0.05, 0.35) * l;
    let cab_h = b.u(0.14, 0.26);
    let cabin = sheared_box(
        v(-w * 0.95, y0 + body_h - 0.01, -l + front),
        v(w * 0.95, y0 + body_h + cab_h, l - 0.01),
        v(0.0, 0.0, b.u(0.0, 0.04)),
        [b.u(0.9, 1.0), b.u(0.85, 0.98)],
    );
    b.push(hexahedron(cabin), glass);
    let ww = b.u(THIN, 0.1);
    let wz = l * b.u(0.6, 0.75);
    wheels(b, w, wr, ww, [-wz, wz], tyre);
}

/// Pickup: a cabin at the front, an open bed behind it.
fn pickup(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.9, 1.0) / 2.0;
    let w = b.u(0.4, 0.48) / 2.0;
    let wr = b.u(0.08, 0.11);
    let body_h = b.u(0.14, 0.2);
    let y0 = wr * 0.75;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let cab_front = -l + b.u(0.25, 0.4) * l;
    let cab_back = cab_front + b.u(0.45, 0.65) * l;
    let cab_h = b.u(0.14, 0.2);
    let cabin = sheared_box(
        v(-w * 0.95, y0 + body_h - 0.01, cab_front),
        v(w * 0.95, y0 + body_h + cab_h, cab_back),
        v(0.0, 0.0, 0.01),
        [0.95, b.u(0.7, 0.9)],
    );
    b.push(hexahedron(cabin), glass);
    let bed_h = b.u(THIN, 0.1);
    let t = THIN;
    let y1 = y0 + body_h - 0.01;
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * t;
        b.cuboid(
            v(x0.min(x1), y1, cab_back),
            v(x0.max(x1), y1 + bed_h, l),
            paint,
        );
    }
    b.cuboid(v(-w, y1, l - t), v(w, y1 + bed_h, l), paint);
    let ww = b.u(THIN, 0.1);
    let wz = [-l * b.u(0.6, 0.72), l * b.u(0.55, 0.7)];
    wheels(b, w, wr, ww, wz, tyre);
}

/// Sports car: low and wide, a low swept cabin, big wheels.
fn sports_car(b: &mut Builder) {
    let paint = b.color();
    let glass = b.dark();
    let tyre = b.dark();
    let l = b.u(0.85, 1.0) / 2.0;
    let w = b.u(0.44, 0.52) / 2.0;
    let wr = b.u(0.08, 0.1);
    let body_h = b.u(0.07, 0.11);
    let y0 = wr * 0.6;
    let nose = sheared_box(
        v(-w, y0, -l),
        v(w, y0 + body_h, l),
        v(0.0, 0.0, 0.0),
        [1.0, b.u(0.9, 1.0)],
    );
    b.push(hexahedron(nose), paint);
    let cab_l = b.u(0.3, 0.45) * l;
    let cab_h = b.u(0.06, 0.1);
    let cab_z = b.u(0.0, 0.2) * l;
    let cabin = sheared_box(
        v(-w * 0.85, y0 + body_h - 0.01, cab_z - cab_l),
        v(w * 0.85, y0 + body_h + cab_h, cab_z + cab_l),
        v(0.0, 0.0, b.u(0.02, 0.06)),
        [b.u(0.8, 0.9), b.u(0.4, 0.6)],
    );
    b.push(hexahedron(cabin), glass);
    if b.chance(0.4) {
        let sp = THIN;
        b.cuboid(
            v(-w * 0.9, y0 + body_h + 0.04, l - 0.08),
            v(w * 0.9, y0 + body_h + 0.04 + sp, l - 0.01),
            paint,
        );
        for sx in [-1.0, 1.0] {
            let x = sx * w * 0.6;
            b.cuboid(
                v(x - sp / 2.0, y0 + body_h - 0.01, l - 0.03 - sp),
                v(x + sp / 2.0, y0 + body_h + 0.04 + sp / 2.0, l - 0.03),
                paint,
            );
        }
    }
    let ww = b.u(THIN, 0.1);
    let wz = l * b.u(0.6, 0.72);
    wheels(b, w, wr, ww, [-wz, wz], tyre);
}

/// The four wheels of a car: `wr` radius, `ww` wide, at `±wz` along its length.
fn wheels(b: &mut Builder, w: f64, wr: f64, ww: f64, wz: [f64; 2], tyre: [f32; 3]) {
    for sx in [-1.0, 1.0] {
        for z in wz {
            let x = sx * (w - ww * 0.3);
            b.frustum(v(x - ww / 2.0, wr, z), v(x + ww / 2.0, wr, z), wr, wr, tyre);
        }
    }
}
