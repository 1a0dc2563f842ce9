// A view as the setup and backward kernels read it, and the matrix projection. Twin of
// `GpuView` (src/raster/setup.rs) and of `camera::Projection`.
#ifndef SOFTVK_VIEW_GLSL
#define SOFTVK_VIEW_GLSL

#define PROJ_PERSPECTIVE 0u
#define PROJ_ORTHOGRAPHIC 1u
#define PROJ_MATRIX 2u

// Twin of `GpuView` (src/raster/setup.rs). 96 bytes.
struct View {
    vec4 rows[3];    // look-at rotation rows x, y, z (w unused); matrix: the rows of P
    vec4 eye;        // eye position (w unused)
    vec4 dist;       // matrix: Brown k1, k2, p1, p2
    uint projection; // PROJ_*
    float param;     // perspective: tan(viewing angle); orthographic: scale; matrix: orig_size
    float k3;        // matrix: Brown k3
    uint mesh;       // the batch's mesh this view shows
};

// `Projection::project_matrix` (SoftRas `projection`): P (p, 1), divide by z + 1e-5, Brown
// distortion, then pixels to [-1, 1] by orig_size; depth is P's third row, undivided.
vec3 project_matrix(View view, vec3 p) {
    float x = view.rows[0].x * p.x + view.rows[0].y * p.y + view.rows[0].z * p.z + view.rows[0].w;
    float y = view.rows[1].x * p.x + view.rows[1].y * p.y + view.rows[1].z * p.z + view.rows[1].w;
    float z = view.rows[2].x * p.x + view.rows[2].y * p.y + view.rows[2].z * p.z + view.rows[2].w;
    float x1 = fm_div_rn(x, z + 1e-5);  // correctly rounded, as torch's composed projection
    float y1 = fm_div_rn(y, z + 1e-5);
    float k1 = view.dist.x;
    float k2 = view.dist.y;
    float p1 = view.dist.z;
    float p2 = view.dist.w;
    float r2 = x1 * x1 + y1 * y1;
    float radial = 1.0 + k1 * r2 + k2 * r2 * r2 + view.k3 * r2 * r2 * r2;
    float x2 = x1 * radial + 2.0 * p1 * x1 * y1 + p2 * (r2 + 2.0 * x1 * x1);
    float y2 = y1 * radial + p1 * (r2 + 2.0 * y1 * y1) + 2.0 * p2 * x1 * y1;
    float half_size = view.param * 0.5;
    return vec3(fm_div_rn(x2 - half_size, half_size), fm_div_rn(y2 - half_size, half_size), z);
}

// `Camera::to_screen`: perspective p_c = R (p - eye), then (x / z / tan a, y / z / tan a, z);
// orthographic (s x, s y, z); or the matrix projection.
vec3 to_screen(View view, vec3 p) {
    if (view.projection == PROJ_MATRIX) {
        return project_matrix(view, p);
    }
    vec3 d = p - view.eye.xyz;
    vec3 c = vec3(view.rows[0].x * d.x + view.rows[0].y * d.y + view.rows[0].z * d.z,
                  view.rows[1].x * d.x + view.rows[1].y * d.y + view.rows[1].z * d.z,
                  view.rows[2].x * d.x + view.rows[2].y * d.y + view.rows[2].z * d.z);
    if (view.projection == PROJ_PERSPECTIVE) {
        // Correctly rounded (as torch's composed projection and the f64 twin's rounding expect):
        // once per vertex (`vertex_project.comp`), so its cost is small beside the fine pass.
        return vec3(fm_div_rn(fm_div_rn(c.x, c.z), view.param),
                    fm_div_rn(fm_div_rn(c.y, c.z), view.param), c.z);
    }
    return vec3(c.x * view.param, c.y * view.param, c.z);
}

#endif
