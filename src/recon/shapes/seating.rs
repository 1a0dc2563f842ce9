//! Recipes for the things one sits on: chairs (four-legged, office, stool, armchair, sled),
//! benches (legged, picnic, ottoman, slab-ended) and sofas.

use super::builder::{Builder, THIN, hexahedron, sheared_box, style, v};

pub(super) fn chair(b: &mut Builder) {
    match style(b, 5) {
        0 => four_leg_chair(b),
        1 => office_chair(b),
        2 => stool(b),
        3 => armchair(b),
        _ => sled_chair(b),
    }
}

/// Sled chair: seat and back on a bent-tube frame: a runner on the floor each side, rising at
/// the front to the seat and at the back up the backrest.
fn sled_chair(b: &mut Builder) {
    let shell = b.color();
    let metal = if b.chance(0.5) { b.dark() } else { b.color() };
    let w = b.u(0.4, 0.56) / 2.0;
    let d = b.u(0.38, 0.52) / 2.0;
    let h = b.u(0.38, 0.5);
    let t = b.u(THIN, 0.09);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), shell);
    let bh = b.u(0.3, 0.5);
    let bt = b.u(THIN, 0.08);
    let lean = b.u(0.0, 0.1);
    let back = sheared_box(
        v(-w, h + t * 0.5, d - bt),
        v(w, h + t + bh, d),
        v(0.0, 0.0, lean),
        [b.u(0.85, 1.0), 1.0],
    );
    b.push(hexahedron(back), shell);
    let tr = b.u(THIN / 2.0, 0.035);
    let reach = b.u(0.0, 0.08);
    let x = w * b.u(0.75, 0.95);
    for sx in [-1.0, 1.0] {
        let x = sx * x;
        let front = v(x, tr, -d - reach);
        let rear = v(x, tr, d + reach * 0.5);
        b.frustum(front, rear, tr, tr, metal);
        b.frustum(front, v(x, h + t / 2.0, -d + 0.03), tr, tr, metal);
        b.frustum(
            rear,
            v(x, h + t + bh * 0.8, d - bt / 2.0 + lean * 0.8),
            tr,
            tr,
            metal,
        );
    }
}

fn four_leg_chair(b: &mut Builder) {
    let seat_color = b.color();
    let back_color = if b.chance(0.6) { seat_color } else { b.color() };
    let leg_color = b.color();
    let w = b.u(0.38, 0.64) / 2.0;
    let d = b.u(0.36, 0.6) / 2.0;
    let t = b.u(THIN, 0.1);
    let h = b.u(0.32, 0.5);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), seat_color);
    // Legs: square posts, round posts, or splayed posts.
    let style = (b.rng.unit() * 3.0) as u32;
    let s = b.u(THIN, 0.09) / 2.0;
    let splay = if style == 2 { b.u(0.03, 0.07) } else { 0.0 };
    let inset = b.u(0.0, 0.04) + s;
    for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let top = v(sx * (w - inset), h + t / 2.0, sz * (d - inset));
        let foot = v(top.x + sx * splay, 0.0, top.z + sz * splay);
        match style {
            0 => b.cuboid(
                v(top.x - s, 0.0, top.z - s),
                v(top.x + s, h + t / 2.0, top.z + s),
                leg_color,
            ),
            _ => b.frustum(foot, top, s * 1.1, s * 1.1, leg_color),
        }
    }
    // Back at the rear (+z), tilted backwards.
    let bh = b.u(0.35, 0.6);
    let bt = b.u(THIN, 0.095);
    let tilt = b.u(0.0, 0.1);
    let taper = b.u(0.8, 1.05);
    let back = sheared_box(
        v(-w, h + t * 0.5, d - bt),
        v(w, h + t + bh, d),
        v(0.0, 0.0, tilt),
        [taper, 1.0],
    );
    b.push(hexahedron(back), back_color);
    if b.chance(0.35) {
        let ah = b.u(0.16, 0.26);
        let aw = b.u(THIN, 0.095);
        for sx in [-1.0, 1.0] {
            let x0 = sx * w;
            let x1 = x0 - sx * aw;
            // Support post at the front, then the rest on top of it.
            b.cuboid(
                v(x0.min(x1), h + t, -d + 0.02),
                v(x0.max(x1), h + t + ah, -d + 0.02 + aw),
                back_color,
            );
            b.cuboid(
                v(x0.min(x1), h + t + ah - aw, -d),
                v(x0.max(x1), h + t + ah, d),
                back_color,
            );
        }
    }
}

/// Office chair: seat and back on a column, five spokes with casters.
fn office_chair(b: &mut Builder) {
    let shell = b.color();
    let metal = b.dark();
    let w = b.u(0.4, 0.55) / 2.0;
    let d = b.u(0.38, 0.5) / 2.0;
    let h = b.u(0.4, 0.55);
    let t = b.u(0.06, 0.1);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), shell);
    let cr = b.u(THIN / 2.0, 0.045);
    b.frustum(v(0.0, 0.06, 0.0), v(0.0, h + 0.01, 0.0), cr, cr, metal);
    let spoke = b.u(0.22, 0.3);
    let sr = THIN / 2.0 * b.u(1.0, 1.4);
    let turn = b.u(0.0, 1.0);
    for k in 0..5 {
        let a = std::f64::consts::TAU * (f64::from(k) + turn) / 5.0;
        let end = v(spoke * a.cos(), 0.06, spoke * a.sin());
        b.frustum(v(0.0, 0.06, 0.0), end, sr, sr, metal);
        b.frustum(end - v(0.0, 0.06, 0.0), end, sr * 1.2, sr * 1.2, metal);
    }
    let bh = b.u(0.3, 0.55);
    let bt = b.u(THIN, 0.1);
    let back = sheared_box(
        v(-w * 0.9, h + t, d - bt),
        v(w * 0.9, h + t + bh, d),
        v(0.0, 0.0, b.u(0.02, 0.1)),
        [b.u(0.75, 1.0), 1.0],
    );
    b.push(hexahedron(back), shell);
    if b.chance(0.5) {
        let ah = b.u(0.15, 0.22);
        let aw = THIN * 1.2;
        for sx in [-1.0, 1.0] {
            let x = sx * (w - aw / 2.0);
            b.cuboid(
                v(x - aw / 2.0, h + t, -aw / 2.0),
                v(x + aw / 2.0, h + t + ah, aw / 2.0),
                metal,
            );
            b.cuboid(
                v(x - aw, h + t + ah - aw, -d * 0.7),
                v(x + aw, h + t + ah, d * 0.5),
                metal,
            );
        }
    }
}

/// Stool: a round (or square) seat on three or four splayed legs, no back.
fn stool(b: &mut Builder) {
    let seat = b.color();
    let wood = if b.chance(0.5) { seat } else { b.color() };
    let r = b.u(0.14, 0.22);
    let h = b.u(0.45, 0.8);
    let t = b.u(THIN, 0.1);
    if b.chance(0.6) {
        b.frustum(v(0.0, h, 0.0), v(0.0, h + t, 0.0), r, r, seat);
    } else {
        b.cuboid(v(-r, h, -r), v(r, h + t, r), seat);
    }
    let n = 3 + style(b, 2);
    let s = b.u(THIN, 0.085) / 2.0;
    let splay = b.u(0.02, 0.12);
    let turn = b.u(0.0, 1.0);
    let ring = b.chance(0.5);
    let ry = h * b.u(0.25, 0.4);
    for k in 0..n {
        let a = std::f64::consts::TAU * (f64::from(k) + turn) / f64::from(n);
        let (c, sn) = (a.cos(), a.sin());
        let top = v(c * r * 0.65, h + t / 2.0, sn * r * 0.65);
        let foot = v(c * (r * 0.65 + splay), 0.0, sn * (r * 0.65 + splay));
        b.frustum(foot, top, s, s, wood);
        if ring {
            let f = ry / (h + t / 2.0);
            let p = foot + (top - foot) * f;
            let a2 = std::f64::consts::TAU * (f64::from(k) + 1.0 + turn) / f64::from(n);
            let q_foot = v(
                a2.cos() * (r * 0.65 + splay),
                0.0,
                a2.sin() * (r * 0.65 + splay),
            );
            let q_top = v(a2.cos() * r * 0.65, h + t / 2.0, a2.sin() * r * 0.65);
            let q = q_foot + (q_top - q_foot) * f;
            b.frustum(p, q, s, s, wood);
        }
    }
}

/// Armchair: a low, wide seat between solid sides that reach the floor, a solid back.
fn armchair(b: &mut Builder) {
    let cloth = b.color();
    let w = b.u(0.6, 0.85) / 2.0;
    let d = b.u(0.55, 0.75) / 2.0;
    let h = b.u(0.25, 0.38);
    let at = b.u(0.08, 0.14);
    let ah = h + b.u(0.12, 0.22);
    b.cuboid(v(-w + at, 0.05, -d), v(w - at, h, d), cloth);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * at;
        b.cuboid(v(x0.min(x1), 0.0, -d), v(x0.max(x1), ah, d), cloth);
    }
    let bt = b.u(0.1, 0.16);
    let bh = b.u(0.55, 0.8);
    let back = sheared_box(
        v(-w, 0.0, d - bt),
        v(w, bh, d),
        v(0.0, 0.0, b.u(0.0, 0.08)),
        [1.0, 1.0],
    );
    b.push(hexahedron(back), cloth);
    if b.chance(0.6) {
        let cushion = b.color();
        let ch = b.u(0.05, 0.1);
        b.cuboid(
            v(-w + at + 0.01, h - 0.01, -d - 0.01),
            v(w - at - 0.01, h + ch, d - bt),
            cushion,
        );
    }
}

pub(super) fn bench(b: &mut Builder) {
    match style(b, 4) {
        0 => leg_bench(b),
        1 => picnic_bench(b),
        2 => ottoman_bench(b),
        _ => slab_bench(b),
    }
}

/// Slab-ended bench: a seat between two solid end panels that rise above it as arms, often a
/// leaning back between the arms.
fn slab_bench(b: &mut Builder) {
    let wood = b.color();
    let ends = if b.chance(0.5) { wood } else { b.color() };
    let l = b.u(0.75, 1.0) / 2.0;
    let d = b.u(0.28, 0.45) / 2.0;
    let h = b.u(0.3, 0.45);
    let t = b.u(THIN, 0.1);
    let et = b.u(THIN, 0.12);
    let arm = b.u(0.0, 0.2);
    b.cuboid(v(-l + et, h, -d), v(l - et, h + t, d), wood);
    for sx in [-1.0, 1.0] {
        let x0 = sx * l;
        let x1 = x0 - sx * et;
        b.cuboid(v(x0.min(x1), 0.0, -d), v(x0.max(x1), h + t + arm, d), ends);
    }
    if b.chance(0.6) {
        let bt = b.u(THIN, 0.08);
        let bh = b.u(0.2, 0.4);
        let back = sheared_box(
            v(-l + et, h + t * 0.5, d - bt),
            v(l - et, h + t + bh, d),
            v(0.0, 0.0, b.u(0.0, 0.08)),
            [1.0, 1.0],
        );
        b.push(hexahedron(back), wood);
    }
}

fn leg_bench(b: &mut Builder) {
    let wood = b.color();
    let frame = if b.chance(0.5) { wood } else { b.color() };
    let l = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.24, 0.4) / 2.0;
    let h = b.u(0.32, 0.45);
    let t = b.u(THIN, 0.095);
    b.cuboid(v(-l, h, -d), v(l, h + t, d), wood);
    let slab_legs = b.chance(0.5);
    let s = b.u(THIN, 0.095) / 2.0;
    let inset = b.u(0.02, 0.1) + s;
    for sx in [-1.0, 1.0] {
        let x = sx * (l - inset);
        if slab_legs {
            b.cuboid(v(x - s, 0.0, -d), v(x + s, h + t / 2.0, d), frame);
        } else {
            for sz in [-1.0, 1.0] {
                let z = sz * (d - s - 0.01);
                b.cuboid(v(x - s, 0.0, z - s), v(x + s, h + t / 2.0, z + s), frame);
            }
        }
    }
    if b.chance(0.6) {
        let slats = 1 + (b.rng.unit() * 3.0) as u32;
        let bh = b.u(0.2, 0.35);
        let gap = bh / f64::from(slats);
        let st = THIN;
        for k in 0..slats {
            let y = h + t + gap * f64::from(k) + gap * 0.3;
            b.cuboid(v(-l, y, d - st), v(l, y + (gap * 0.7).max(st), d), wood);
        }
        for sx in [-1.0, 1.0] {
            let x = sx * (l - inset);
            b.cuboid(
                v(x - s, h + t / 2.0, d - st),
                v(x + s, h + t + bh, d),
                frame,
            );
        }
    }
}

/// Picnic bench: a seat on two A-frames of crossed legs, a stretcher between them.
fn picnic_bench(b: &mut Builder) {
    let wood = b.color();
    let l = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.22, 0.34) / 2.0;
    let h = b.u(0.35, 0.45);
    let t = b.u(THIN, 0.095);
    b.cuboid(v(-l, h, -d), v(l, h + t, d), wood);
    let s = b.u(THIN, 0.085) / 2.0;
    let inset = b.u(0.08, 0.2);
    let spread = b.u(0.1, 0.2);
    for sx in [-1.0, 1.0] {
        let x = sx * (l - inset);
        for sz in [-1.0, 1.0] {
            b.frustum(
                v(x, 0.0, sz * (d + spread)),
                v(x, h + t / 2.0, -sz * d * 0.3),
                s,
                s,
                wood,
            );
        }
    }
    let sy = h * 0.4;
    b.cuboid(v(-l + inset, sy - s, -s), v(l - inset, sy + s, s), wood);
}

/// Ottoman bench: a padded block, on the floor or on short feet.
fn ottoman_bench(b: &mut Builder) {
    let cloth = b.color();
    let l = b.u(0.75, 1.0) / 2.0;
    let d = b.u(0.3, 0.45) / 2.0;
    let h = b.u(0.3, 0.42);
    let feet = b.chance(0.5);
    let y0 = if feet { b.u(0.05, 0.12) } else { 0.0 };
    b.cuboid(v(-l, y0, -d), v(l, h, d), cloth);
    if feet {
        let wood = b.color();
        let f = b.u(THIN, 0.085) / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (l - f - 0.03), 0.0, sz * (d - f - 0.03));
            b.cuboid(c - v(f, 0.0, f), c + v(f, y0 + 0.01, f), wood);
        }
    }
    if b.chance(0.5) {
        let top = b.color();
        let th = b.u(THIN, 0.09);
        b.cuboid(
            v(-l + 0.01, h - 0.01, -d + 0.01),
            v(l - 0.01, h + th, d - 0.01),
            top,
        );
    }
}

pub(super) fn sofa(b: &mut Builder) {
    let cloth = b.color();
    let cushion = if b.chance(0.5) { cloth } else { b.color() };
    let w = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.38, 0.52) / 2.0;
    let y0 = b.u(0.0, 0.06);
    let base_h = b.u(0.16, 0.26);
    b.cuboid(v(-w, y0, -d), v(w, y0 + base_h, d), cloth);
    if y0 > 0.02 {
        let f = THIN / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - 0.05), 0.0, sz * (d - 0.05));
            b.cuboid(
                c - v(f, 0.0, f),
                c + v(f, (y0 + 0.01).max(THIN), f),
                cushion,
            );
        }
    }
    let bt = b.u(0.08, 0.14);
    let bh = b.u(0.18, 0.32);
    let back = sheared_box(
        v(-w, y0 + base_h - 0.01, d - bt),
        v(w, y0 + base_h + bh, d),
        v(0.0, 0.0, b.u(0.0, 0.05)),
        [1.0, 1.0],
    );
    b.push(hexahedron(back), cloth);
    let at = b.u(0.07, 0.13);
    let ah = b.u(0.08, 0.18);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * at;
        b.cuboid(
            v(x0.min(x1), y0 + base_h - 0.01, -d),
            v(x0.max(x1), y0 + base_h + ah, d - bt * 0.5),
            cloth,
        );
    }
    let n = 1 + (b.rng.unit() * 3.0) as u32;
    let ct = b.u(THIN, 0.1);
    let inner = w - at;
    let cw = 2.0 * inner / f64::from(n);
    for k in 0..n {
        let x = -inner + cw * f64::from(k);
        b.cuboid(
            v(x + 0.005, y0 + base_h - 0.01, -d),
            v(x + cw - 0.005, y0 + base_h + ct, d - bt),
            cushion,
        );
    }
}
