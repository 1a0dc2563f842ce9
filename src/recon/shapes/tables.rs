//! Recipes for tables (legged, coffee, desk, trestle, pedestal on a cross foot) and cabinets: a
//! top or a body on legs, panels or feet.

use super::builder::{Builder, THIN, hexahedron, style, v};

pub(super) fn table(b: &mut Builder) {
    match style(b, 5) {
        0 => leg_table(b),
        1 => coffee_table(b),
        2 => desk(b),
        3 => trestle_table(b),
        _ => cross_foot_table(b),
    }
}

/// Pedestal table on a cross foot: a square or round top, from bistro to bar height, on a
/// column standing on two crossed feet (turned by any angle).
fn cross_foot_table(b: &mut Builder) {
    let top_color = b.color();
    let metal = if b.chance(0.5) { b.dark() } else { b.color() };
    let h = b.u(0.45, 0.95);
    let t = b.u(THIN, 0.08);
    let r = b.u(0.25, 0.5);
    if b.chance(0.5) {
        b.frustum(v(0.0, h, 0.0), v(0.0, h + t, 0.0), r, r, top_color);
    } else {
        let q = r * b.u(0.8, 1.0);
        b.cuboid(v(-q, h, -q), v(q, h + t, q), top_color);
    }
    let pr = b.u(THIN / 2.0, 0.05);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, h + t / 2.0, 0.0), pr, pr, metal);
    let reach = r * b.u(0.6, 0.95);
    let fh = b.u(THIN, 0.07);
    let turn = b.u(0.0, std::f64::consts::FRAC_PI_2);
    for k in 0..2 {
        let a = turn + std::f64::consts::FRAC_PI_2 * f64::from(k);
        let (c, sn) = (a.cos() * reach, a.sin() * reach);
        // A foot is a flat bar: a cylinder of width fh would roll; a box turned by `a`.
        let half = fh / 2.0;
        let (px, pz) = (-a.sin() * half, a.cos() * half);
        b.push(
            hexahedron(std::array::from_fn(|i| {
                let end = if i & 1 != 0 { 1.0 } else { -1.0 };
                let side = if i & 4 != 0 { 1.0 } else { -1.0 };
                let y = if i & 2 != 0 { fh } else { 0.0 };
                v(end * c + side * px, y, end * sn + side * pz)
            })),
            metal,
        );
    }
}

fn leg_table(b: &mut Builder) {
    let top_color = b.color();
    let leg_color = if b.chance(0.5) { top_color } else { b.color() };
    let h = b.u(0.45, 0.8);
    let t = b.u(THIN, 0.095);
    let round = b.chance(0.3);
    if round {
        let r = b.u(0.3, 0.5);
        b.frustum(v(0.0, h, 0.0), v(0.0, h + t, 0.0), r, r, top_color);
        if b.chance(0.6) {
            // Pedestal: column and foot.
            let pr = b.u(0.03, 0.07);
            b.frustum(
                v(0.0, 0.0, 0.0),
                v(0.0, h + t / 2.0, 0.0),
                pr,
                pr,
                leg_color,
            );
            let fr = b.u(0.18, 0.3);
            let ft = b.u(THIN, 0.085);
            b.frustum(v(0.0, 0.0, 0.0), v(0.0, ft, 0.0), fr, fr * 0.8, leg_color);
        } else {
            let s = b.u(THIN, 0.085) / 2.0;
            let q = r * 0.6;
            for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                let c = v(sx * q * 0.707, 0.0, sz * q * 0.707);
                b.frustum(c, c + v(0.0, h + t / 2.0, 0.0), s, s, leg_color);
            }
        }
    } else {
        let w = b.u(0.5, 1.0) / 2.0;
        let d = b.u(0.35, 0.75) / 2.0;
        b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
        let s = b.u(THIN, 0.1) / 2.0;
        let inset = b.u(0.0, 0.06) + s;
        let round_legs = b.chance(0.4);
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - inset), 0.0, sz * (d - inset));
            if round_legs {
                b.frustum(c, c + v(0.0, h + t / 2.0, 0.0), s, s * 0.8, leg_color);
            } else {
                b.cuboid(c - v(s, 0.0, s), c + v(s, h + t / 2.0, s), leg_color);
            }
        }
        if b.chance(0.3) {
            let sh = b.u(0.08, 0.2);
            b.cuboid(
                v(-w + inset, sh, -d + inset),
                v(w - inset, sh + THIN, d - inset),
                leg_color,
            );
        }
    }
}

/// Coffee table: low and wide, on four short legs or two slab ends, often a shelf.
fn coffee_table(b: &mut Builder) {
    let top_color = b.color();
    let leg_color = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.75, 1.0) / 2.0;
    let d = b.u(0.4, 0.75) / 2.0;
    let h = b.u(0.22, 0.38);
    let t = b.u(THIN, 0.11);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let s = b.u(THIN, 0.11) / 2.0;
    let inset = b.u(0.0, 0.08) + s;
    if b.chance(0.5) {
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - inset), 0.0, sz * (d - inset));
            b.cuboid(c - v(s, 0.0, s), c + v(s, h + t / 2.0, s), leg_color);
        }
    } else {
        for sx in [-1.0, 1.0] {
            let x = sx * (w - inset);
            b.cuboid(v(x - s, 0.0, -d), v(x + s, h + t / 2.0, d), leg_color);
        }
    }
    if b.chance(0.5) {
        let sh = b.u(0.04, h * 0.5);
        b.cuboid(
            v(-w + inset, sh, -d + inset * 0.5),
            v(w - inset, sh + THIN, d - inset * 0.5),
            leg_color,
        );
    }
}

/// Desk: a top on two side panels, often a drawer pedestal and a modesty panel at the back.
fn desk(b: &mut Builder) {
    let top_color = b.color();
    let body = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.8, 1.0) / 2.0;
    let d = b.u(0.4, 0.6) / 2.0;
    let h = b.u(0.55, 0.75);
    let t = b.u(THIN, 0.085);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let pt = b.u(THIN, 0.095);
    let side = if b.chance(0.5) { -1.0 } else { 1.0 };
    let pedestal = b.chance(0.6);
    let pw = b.u(0.25, 0.4);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = if pedestal && sx == side {
            x0 - sx * pw
        } else {
            x0 - sx * pt
        };
        b.cuboid(v(x0.min(x1), 0.0, -d), v(x0.max(x1), h + t / 2.0, d), body);
    }
    if b.chance(0.6) {
        let mh = h * b.u(0.3, 0.7);
        b.cuboid(v(-w + pt, h - mh, d - pt), v(w - pt, h + t / 2.0, d), body);
    }
}

/// Trestle table: a long top on two I-shaped ends (foot, post, cleat) joined by a stretcher.
fn trestle_table(b: &mut Builder) {
    let top_color = b.color();
    let wood = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.8, 1.0) / 2.0;
    let d = b.u(0.35, 0.6) / 2.0;
    let h = b.u(0.5, 0.75);
    let t = b.u(THIN, 0.1);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let s = b.u(THIN, 0.1) / 2.0;
    let ft = b.u(THIN, 0.095);
    let inset = b.u(0.08, 0.2);
    for sx in [-1.0, 1.0] {
        let x = sx * (w - inset);
        b.cuboid(v(x - s, 0.0, -d * 0.9), v(x + s, ft, d * 0.9), wood);
        b.cuboid(v(x - s, ft - 0.01, -s), v(x + s, h - ft + 0.01, s), wood);
        b.cuboid(
            v(x - s, h - ft, -d * 0.85),
            v(x + s, h + 0.005, d * 0.85),
            wood,
        );
    }
    let sy = h * b.u(0.3, 0.6);
    let st = THIN / 2.0 * 1.2;
    b.cuboid(v(-w + inset, sy - st, -st), v(w - inset, sy + st, st), wood);
}

pub(super) fn cabinet(b: &mut Builder) {
    let wood = b.color();
    let front = if b.chance(0.5) { wood } else { b.color() };
    let handle = b.dark();
    let w = b.u(0.45, 0.9) / 2.0;
    let h = b.u(0.55, 1.0);
    let d = b.u(0.3, 0.5) / 2.0;
    let feet = b.chance(0.4);
    let y0 = if feet { b.u(0.04, 0.1) } else { 0.0 };
    b.cuboid(v(-w, y0, -d), v(w, y0 + h, d), wood);
    if feet {
        let f = b.u(THIN, 0.085) / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - f - 0.02), 0.0, sz * (d - f - 0.02));
            b.cuboid(c - v(f, 0.0, f), c + v(f, (y0 + 0.01).max(THIN), f), wood);
        }
    }
    // Doors (side by side) or drawers (stacked), proud of the front by a little.
    let drawers = b.chance(0.5);
    let n = 2 + (b.rng.unit() * 2.0) as u32;
    let m = 0.025;
    let proud = 0.02;
    for k in 0..n {
        let f = f64::from(k);
        let (lo, hi) = if drawers {
            let step = (h - 2.0 * m) / f64::from(n);
            (
                v(-w + m, y0 + m + step * f + 0.005, -d - proud),
                v(w - m, y0 + m + step * (f + 1.0) - 0.005, -d - proud + THIN),
            )
        } else {
            let step = (2.0 * w - 2.0 * m) / f64::from(n);
            (
                v(-w + m + step * f + 0.005, y0 + m, -d - proud),
                v(
                    -w + m + step * (f + 1.0) - 0.005,
                    y0 + h - m,
                    -d - proud + THIN,
                ),
            )
        };
        b.cuboid(lo, hi, front);
        let c = (lo + hi) / 2.0;
        let hs = THIN / 2.0;
        b.cuboid(
            v(c.x - 2.0 * hs, c.y - hs, lo.z - proud),
            v(c.x + 2.0 * hs, c.y + hs, lo.z - proud + THIN),
            handle,
        );
    }
}
