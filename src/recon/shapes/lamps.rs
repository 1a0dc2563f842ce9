//! Recipes for lamps (desk, floor, arc, vase, tripod) and displays: a base, a pole or neck, and
//! what it holds up (a shade, a screen).

use super::builder::{Builder, THIN, style, v};

pub(super) fn lamp(b: &mut Builder) {
    match style(b, 5) {
        0 => desk_lamp(b),
        1 => floor_lamp(b),
        2 => arc_lamp(b),
        3 => vase_lamp(b),
        _ => tripod_lamp(b),
    }
}

/// Tripod lamp: three splayed legs meeting under a drum or cone shade, with a short stem from
/// where they meet.
fn tripod_lamp(b: &mut Builder) {
    let wood = b.color();
    let shade_color = b.color();
    let h = b.u(0.45, 0.85);
    let spread = h * b.u(0.25, 0.45);
    let meet = h * b.u(0.7, 0.85);
    let lr = THIN / 2.0 * b.u(1.0, 1.4);
    let turn = b.u(0.0, 1.0);
    for k in 0..3 {
        let a = std::f64::consts::TAU * (f64::from(k) + turn) / 3.0;
        let foot = v(spread * a.cos(), 0.0, spread * a.sin());
        b.frustum(foot, v(0.0, meet, 0.0), lr, lr, wood);
    }
    b.frustum(v(0.0, meet - 0.02, 0.0), v(0.0, h, 0.0), lr, lr, wood);
    let sh = b.u(0.14, 0.3);
    let r = b.u(0.12, 0.25);
    let r_top = r * b.u(0.5, 1.0);
    b.frustum(
        v(0.0, h - sh * 0.5, 0.0),
        v(0.0, h + sh * 0.5, 0.0),
        r,
        r_top,
        shade_color,
    );
}

fn desk_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let base_r = b.u(0.1, 0.18);
    let base_t = b.u(THIN, 0.085);
    let round_base = b.chance(0.6);
    if round_base {
        b.frustum(
            v(0.0, 0.0, 0.0),
            v(0.0, base_t, 0.0),
            base_r,
            base_r * 0.85,
            metal,
        );
    } else {
        b.cuboid(v(-base_r, 0.0, -base_r), v(base_r, base_t, base_r), metal);
    }
    let pr = THIN / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.5, 0.8);
    let bent = b.chance(0.45);
    let top = if bent {
        let knee = v(0.0, h * b.u(0.55, 0.75), 0.0);
        b.frustum(v(0.0, 0.0, 0.0), knee, pr, pr, metal);
        let reach = b.u(0.15, 0.3);
        let head = knee + v(0.0, h * 0.35, -reach);
        b.frustum(knee, head, pr, pr, metal);
        head
    } else {
        let head = v(0.0, h, 0.0);
        b.frustum(v(0.0, 0.0, 0.0), head, pr, pr, metal);
        head
    };
    let sh = b.u(0.14, 0.26);
    let r_low = b.u(0.12, 0.24);
    let r_high = r_low * b.u(0.35, 0.8);
    let drop = b.u(0.3, 0.7) * sh;
    b.frustum(
        top - v(0.0, drop, 0.0),
        top + v(0.0, sh - drop, 0.0),
        r_low,
        r_high,
        shade_color,
    );
}

/// Floor lamp: a round base, a tall pole, a wide drum shade.
fn floor_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let base_r = b.u(0.12, 0.2);
    let base_t = b.u(THIN, 0.075);
    b.frustum(
        v(0.0, 0.0, 0.0),
        v(0.0, base_t, 0.0),
        base_r,
        base_r * 0.9,
        metal,
    );
    let pr = THIN / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.75, 0.9);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, h, 0.0), pr, pr, metal);
    let sh = b.u(0.14, 0.22);
    let r = b.u(0.14, 0.22);
    let r_top = r * b.u(0.75, 1.0);
    b.frustum(
        v(0.0, h - sh * 0.6, 0.0),
        v(0.0, h + sh * 0.4, 0.0),
        r,
        r_top,
        shade_color,
    );
}

/// Arc lamp: a heavy block base, a pole, an arm out over the floor, a shade hanging open-down.
fn arc_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let bs = b.u(0.08, 0.14);
    let bt = b.u(THIN, 0.1);
    b.cuboid(v(-bs, 0.0, -bs), v(bs, bt, bs), metal);
    let pr = THIN / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.6, 0.85);
    let reach = b.u(0.3, 0.5);
    let rise = b.u(0.0, 0.12);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, h, 0.0), pr, pr, metal);
    let knee = v(0.0, h, 0.0);
    let mid = knee + v(0.0, rise, -reach * 0.5);
    let end = v(0.0, h + rise * 0.5, -reach);
    b.frustum(knee, mid, pr, pr, metal);
    b.frustum(mid, end, pr, pr, metal);
    let sh = b.u(0.1, 0.18);
    let r_low = b.u(0.1, 0.18);
    let r_top = r_low * b.u(0.2, 0.45);
    b.frustum(
        end - v(0.0, sh, 0.0),
        end + v(0.0, 0.01, 0.0),
        r_low,
        r_top,
        shade_color,
    );
}

/// Table lamp: a vase-shaped body, a short neck, a drum shade.
fn vase_lamp(b: &mut Builder) {
    let body = b.color();
    let shade_color = b.color();
    let r = b.u(0.09, 0.16);
    let bh = b.u(0.2, 0.35);
    let belly = bh * b.u(0.3, 0.6);
    let foot = r * b.u(0.5, 0.8);
    let shoulder = r * b.u(0.3, 0.6);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, belly, 0.0), foot, r, body);
    b.frustum(v(0.0, belly, 0.0), v(0.0, bh, 0.0), r, shoulder, body);
    let pr = THIN / 2.0 * 1.2;
    let neck = b.u(0.05, 0.15);
    b.frustum(v(0.0, bh - 0.01, 0.0), v(0.0, bh + neck, 0.0), pr, pr, body);
    let sh = b.u(0.15, 0.28);
    let sr = b.u(0.14, 0.24);
    let sr_top = sr * b.u(0.6, 1.0);
    b.frustum(
        v(0.0, bh + neck - sh * 0.3, 0.0),
        v(0.0, bh + neck + sh * 0.7, 0.0),
        sr,
        sr_top,
        shade_color,
    );
}

pub(super) fn display(b: &mut Builder) {
    let frame = b.color();
    let screen = b.dark();
    let w = b.u(0.75, 1.0) / 2.0;
    let sh = b.u(0.45, 0.65);
    let t = b.u(THIN, 0.095);
    let neck_h = b.u(0.12, 0.25);
    let foot_w = b.u(0.25, 0.5) / 2.0;
    let foot_d = b.u(0.15, 0.25) / 2.0;
    let foot_t = b.u(THIN, 0.085);
    b.cuboid(v(-foot_w, 0.0, -foot_d), v(foot_w, foot_t, foot_d), frame);
    let nw = b.u(THIN, 0.12) / 2.0;
    b.cuboid(
        v(-nw, foot_t - 0.01, -THIN / 2.0 + t),
        v(nw, foot_t + neck_h + 0.1, THIN / 2.0 + t),
        frame,
    );
    let y = foot_t + neck_h;
    b.cuboid(v(-w, y, -t / 2.0), v(w, y + sh, t / 2.0), frame);
    // The glass, a thin slab proud of the bezel's front.
    let bezel = b.u(0.015, 0.04);
    b.cuboid(
        v(-w + bezel, y + bezel, -t / 2.0 - 0.01),
        v(w - bezel, y + sh - bezel, -t / 2.0 - 0.01 + THIN),
        screen,
    );
}
