#!/usr/bin/env python3
"""Timing-only probes of issue #11, round three: `probe.py NAME` rewrites the kernels of this
checkout (run it on a clean tree of the commit named below), so that `cargo build --release`
gives a binary whose results are WRONG but whose time says what the removed part costs; compare
it with the unmodified binary by `ab.sh`, then `git checkout kernels/`. Written against dba568f
(the kernels of f928936).

  T1  backward without the lane sums          T4  backward without the face broadcast
  T2  backward without the texel-sharing loop T5  backward without the colour gather
  T3  texel read-modify-write never taken     F1  forward without the colour gather
  T3b texel read-modify-write compiled out    G0  forward: each lane reads its face's first texel
  P1  backward without nearest_edge           G1  forward: every lane reads one texel (a hit)
  P2  backward without the softmax exp        P3  backward depth/clip divisions as products
  D   backward without the per-pair maths     E   backward without the image and aux loads
"""
import pathlib, subprocess, sys

root = pathlib.Path(subprocess.check_output(["git", "rev-parse", "--show-toplevel"], text=True).strip())
GT, RG, RF = "kernels/grad/grad_tiled.comp", "kernels/include/raster_grad.glsl", "kernels/include/raster_fine.glsl"

PROBES = {
    "T1": [(GT, "vec3 sum = lane_sum(hit ? g.screen[c] : vec3(0.0));", "vec3 sum = hit ? g.screen[c] : vec3(0.0);"),
           (GT, "acc[c] += mine ? sum : vec3(0.0);", "acc[c] += sum;")],
    "T2": [(GT, """                        for (uint k = 0u; k < lanes; ++k) {
                            bool same = subgroupShuffle(texel, k) == texel;
                            vec3 value = subgroupShuffle(g.color[0], k);
                            sum += same ? value : vec3(0.0);
                            leader = leader && !(same && k < lane);
                        }""", "                        sum = g.color[0];")],
    "T3": [(GT, "                        if (leader) {", "                        if (leader && pc.chunk_end == 0xFFFFFFFFu) {")],
    "T3b": [(GT, "                        if (leader) {", "                        if (leader && SUBGROUP_SIZE == 12345u) {")],
    "T4": [(GT, "pixel_face_grad(face_shuffle(f, q), fq, u, g)", "pixel_face_grad(f, fq, u, g)")],
    "T5": [(RG, "vec3 c = sample_color(f.mesh, j, wc);", "vec3 c = wc;")],
    "F1": [(RF, "    vec3 color = sample_color(f.mesh, j, wc);", "    vec3 color = wc;")],
    "G0": [(RF, "surface_texel_index(wc, pc.texture_res);\n    return colors[t].rgb;",
            "(surface_texel_index(wc, pc.texture_res) & 0u);\n    return colors[t].rgb;")],
    "G1": [(RF, "    uint t = (mesh * pc.face_count + face) * r2 + surface_texel_index(wc, pc.texture_res);",
            "    uint t = surface_texel_index(wc, pc.texture_res) & 0u;")],
    "P1": [(RG, "float d2 = MODE_DIST == DIST_EUCLIDEAN ? nearest_edge(f, p, ea_pos, edge, ea, eb, t) : 0.0;",
            "float d2 = MODE_DIST == DIST_EUCLIDEAN ? abs(w.x) * 1e-3 : 0.0; edge = f.v[1].xy - f.v[0].xy; ea_pos = f.v[0].xy; t = w.y;")],
    "P2": [(RG, "float e = exp((u.ref_depth - z) * pc.inv_gamma_range);", "float e = (u.ref_depth - z) * pc.inv_gamma_range;")],
    "P3": [(RG, "d_wc[k] = depth ? d_wc[k] + d_inv / zk : d_wc[k];", "d_wc[k] = depth ? d_wc[k] + d_inv * zk : d_wc[k];"),
           (RG, "g.screen[k].z - d_inv * wc[k] / (zk * zk)", "g.screen[k].z - d_inv * wc[k] * (zk * zk)"),
           (RG, "(d_wc[k] - renorm) / sum", "(d_wc[k] - renorm) * sum"),
           (RG, "float d_n = d_w[k] / det;", "float d_n = d_w[k] * det;")],
    "D": [(GT, "bool hit = live && pixel_face_grad(face_shuffle(f, q), fq, u, g);", """Face fqq = face_shuffle(f, q);
                    bool hit = live && fqq.v[0].x < u.p.x;
                    g.screen[0] = fqq.v[0] * u.d_alpha; g.screen[1] = fqq.v[1] * u.d_alpha;
                    g.screen[2] = fqq.v[2] * u.d_alpha; g.color[0] = fqq.v[2] * u.d_rgb;
                    g.color[1] = g.color[0]; g.color[2] = g.color[0]; g.colored = hit;
                    g.texel = fq & 7u;""")],
    "E": [(RG, """    vec4 rgba = image[id];
    PixelAux a = aux[id];""", """    vec4 rgba = g.abgr;
    PixelAux a; a.softmax_sum = g.r + 1.0; a.softmax_ref_depth = g.g; a.alpha_acc = g.b;
    a.alpha_zeros = uint(g.a); a.hard_face = 0u;""")],
}

if len(sys.argv) != 2 or sys.argv[1] not in PROBES:
    sys.exit(__doc__)
for path, old, new in PROBES[sys.argv[1]]:
    f = root / path
    text = f.read_text()
    if old not in text:
        sys.exit(f"{path}: the text this probe replaces is not there (another commit?)")
    f.write_text(text.replace(old, new, 1))
print(f"probe {sys.argv[1]} applied: build, time with ab.sh, then `git checkout kernels/`")
