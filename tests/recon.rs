//! The reconstruction network's GPU pieces against their twins: the decoder's mesh head and
//! colour generator (forward, backward), the batch gather, and the claim the batch rests on — an object turned by
//! a view's rotation and seen from azimuth 0 is the object seen from that view.

mod common;

use common::{gpu, rng};
use rand::RngExt;
use softvk::camera::Camera;
use softvk::fit::deform::cpu::template_terms;
use softvk::gpu::MemoryKind;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::recon::batch::{self, BatchBuffers, BatchGather, BatchShape};
use softvk::recon::colors;
use softvk::recon::decode::{self, MeshDecoder, view_rotation};

/// The reconstruction's template: an icosphere of 642 vertices (the topology of SoftRas's
/// `sphere_642.obj`), turned off the axes and halved.
fn template() -> Mesh {
    softvk::fit::mesh_fit::icosphere_template()
}

fn max_rel(gpu: &[f32], twin: &[f64]) -> f64 {
    let scale = twin.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-30);
    gpu.iter()
        .zip(twin)
        .map(|(&a, &b)| (f64::from(a) - b).abs() / scale)
        .fold(0.0, f64::max)
}

#[test]
fn decoder_forward_and_backward_match_the_twin_and_rerun_bit_for_bit() {
    let Some(ctx) = gpu() else { return };
    let t = template();
    let image = 16u32;
    let dec = MeshDecoder::new(&ctx, &t.positions, image).unwrap();
    let (objects, copies) = (3u32, 2u32);
    let v = t.vertex_count();
    let per = dec.outputs_per_object() as usize;
    let mut r = rng(5);
    let outputs: Vec<f32> = (0..objects as usize * per)
        .map(|_| r.random_range(-2.0f32..2.0))
        .collect();
    let rotations: Vec<[f32; 2]> = (0..objects * copies)
        .map(|i| view_rotation(-15.0 * f64::from(i * 5 % 24)))
        .collect();
    let d_canon: Vec<f32> = (0..objects as usize * 3 * v)
        .map(|_| r.random_range(-1.0f32..1.0))
        .collect();
    let d_pos: Vec<f32> = (0..(objects * copies) as usize * 3 * v)
        .map(|_| r.random_range(-1.0f32..1.0))
        .collect();
    let up = |name: &str, data: &[f32]| ctx.upload_buffer(name, data).unwrap();
    let out_b = up("outputs", &outputs);
    let rot_b = ctx.upload_buffer("rotations", &rotations).unwrap();
    let dc_b = up("d canonical", &d_canon);
    let dp_b = up("d positions", &d_pos);
    let mk = |name: &str, floats: usize| {
        ctx.create_buffer(name, 4 * floats as u64, MemoryKind::Device)
            .unwrap()
    };
    let canon = mk("canonical", objects as usize * 3 * v);
    let pos = mk("positions", (objects * copies) as usize * 3 * v);
    let d_out = mk("d outputs", objects as usize * per);
    let partials = dec.create_partials(&ctx, objects).unwrap();
    let colors = mk("colours", (objects * copies) as usize * 4 * v);
    let d_colors: Vec<f32> = (0..(objects * copies) as usize * 3 * v)
        .map(|_| r.random_range(-1.0f32..1.0))
        .collect();
    let dcol_b = up("d colours", &d_colors);
    let images: Vec<f32> = (0..objects * 4 * image * image)
        .map(|_| r.random_range(0.0f32..1.0))
        .collect();
    let img_b = up("images", &images);
    let generator = dec.color_generator();
    let pooled = mk("pooled", generator.pooled_floats(objects) as usize);
    let palette = mk("palette", generator.palette_floats(objects) as usize);
    let run = || -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
        ctx.submit_and_wait(|rec| {
            dec.record_forward(
                rec,
                objects,
                copies,
                out_b.whole(),
                rot_b.whole(),
                canon.whole(),
                pos.whole(),
            )?;
            dec.record_backward(
                rec,
                objects,
                copies,
                out_b.whole(),
                rot_b.whole(),
                dc_b.whole(),
                dp_b.whole(),
                d_out.whole(),
                partials.whole(),
            )?;
            dec.record_colors(
                rec,
                objects,
                copies,
                out_b.whole(),
                img_b.whole(),
                pooled.whole(),
                palette.whole(),
                colors.whole(),
            )?;
            dec.record_colors_backward(
                rec,
                objects,
                copies,
                out_b.whole(),
                pooled.whole(),
                palette.whole(),
                dcol_b.whole(),
                d_out.whole(),
            )
        })
        .unwrap();
        (
            ctx.read_buffer(&canon, 0, objects as usize * 3 * v)
                .unwrap(),
            ctx.read_buffer(&pos, 0, (objects * copies) as usize * 3 * v)
                .unwrap(),
            ctx.read_buffer(&d_out, 0, objects as usize * per).unwrap(),
            ctx.read_buffer(&colors, 0, (objects * copies) as usize * 4 * v)
                .unwrap(),
        )
    };
    let first = run();
    let (base, signs) = template_terms(&t.positions).unwrap();
    let f64s = |x: &[f32]| x.iter().map(|&a| f64::from(a)).collect::<Vec<f64>>();
    let rot64: Vec<[f64; 2]> = rotations.iter().map(|r| r.map(f64::from)).collect();
    let (c, p) = decode::cpu::forward(&base, &signs, &f64s(&outputs), per, &rot64, copies as usize);
    let mut d = decode::cpu::backward(
        &base,
        &signs,
        &f64s(&outputs),
        per,
        &rot64,
        copies as usize,
        &f64s(&d_canon),
        &f64s(&d_pos),
    );
    assert!(
        max_rel(&first.0, &c) < 1e-6,
        "meshes {}",
        max_rel(&first.0, &c)
    );
    assert!(
        max_rel(&first.1, &p) < 1e-6,
        "copies {}",
        max_rel(&first.1, &p)
    );
    let d_col64: Vec<[f64; 3]> = d_colors
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]].map(f64::from))
        .collect();
    let shape = colors::cpu::Shape {
        vertices: v,
        image: image as usize,
        head: dec.color_head(),
    };
    let images64 = f64s(&images);
    colors::cpu::backward(
        shape,
        &f64s(&outputs),
        &images64,
        objects as usize,
        copies as usize,
        &d_col64,
        &mut d,
    );
    let generated = colors::cpu::forward(shape, &f64s(&outputs), &images64, objects as usize);
    let want_col: Vec<f64> = generated
        .colors
        .iter()
        .flat_map(|c| std::iter::repeat_n(c, copies as usize))
        .flatten()
        .flatten()
        .copied()
        .collect();
    let got_col: Vec<f32> = first.3.chunks(4).flat_map(|c| [c[0], c[1], c[2]]).collect();
    assert!(
        max_rel(&got_col, &want_col) < 1e-6,
        "colours {}",
        max_rel(&got_col, &want_col)
    );
    assert!(first.3.chunks(4).all(|c| c[3] == 0.0));
    // The displacements', the centroids', the sampling and the selection logits' gradients,
    // each against its own scale.
    let sampling = 3 * v + 3 + colors::PALETTE as usize * generator.cells() as usize;
    let group = |i: &usize| match i % per {
        x if x < 3 * v => 0,
        x if x < 3 * v + 3 => 1,
        x if x < sampling => 2,
        _ => 3,
    };
    let names = [
        "displacement",
        "centroid",
        "sampling logit",
        "selection logit",
    ];
    for (g_id, what) in names.iter().enumerate() {
        let idx: Vec<usize> = (0..d.len()).filter(|i| group(i) == g_id).collect();
        let g: Vec<f32> = idx.iter().map(|&i| first.2[i]).collect();
        let tw: Vec<f64> = idx.iter().map(|&i| d[i]).collect();
        assert!(
            max_rel(&g, &tw) < 1e-5,
            "{what} gradient {}",
            max_rel(&g, &tw)
        );
    }
    let second = run();
    assert_eq!(first, second, "a rerun differs");
}

#[test]
fn batch_gather_equals_its_twin_bit_for_bit() {
    let Some(ctx) = gpu() else { return };
    let shape = BatchShape {
        batch: 3,
        pixels: 5 * 7,
        views: 4,
    };
    let objects = 4u32;
    let mut r = rng(9);
    let bytes: Vec<u8> = (0..objects * shape.views * 4 * shape.pixels)
        .map(|_| r.random::<u8>())
        .collect();
    let iterations = 3u32;
    let mut schedule: Vec<[u32; 4]> = (0..iterations * shape.batch)
        .map(|_| {
            [
                r.random_range(0..objects),
                r.random_range(0..shape.views),
                r.random_range(0..shape.views),
                0,
            ]
        })
        .collect();
    batch::cpu::check_schedule(&schedule, objects, shape.views).unwrap();
    let table: Vec<[f32; 2]> = (0..shape.views)
        .map(|v| view_rotation(-15.0 * f64::from(v)))
        .collect();
    // Only the views the schedule names reach the GPU, each entry's pair at its slot.
    let staged = batch::stage_views(&ctx, &bytes, shape, &mut schedule).unwrap();
    assert!(schedule.iter().enumerate().all(|(i, e)| e[3] == i as u32));
    let staged_bytes: &[u8] = bytemuck::cast_slice(&staged);
    let images = ctx.upload_buffer("staged views", &staged).unwrap();
    let sched = ctx.upload_buffer("schedule", &schedule).unwrap();
    let tab = ctx.upload_buffer("view rotations", &table).unwrap();
    let (n, px) = (shape.batch as usize, shape.pixels as usize);
    let mk = |name: &str, floats: usize| {
        ctx.create_buffer(name, 4 * floats as u64, MemoryKind::Device)
            .unwrap()
    };
    let (input, targets, rotations) = (
        mk("input", 4 * n * px),
        mk("targets", 2 * n * px),
        mk("rot", 4 * n),
    );
    let target_images = mk("target images", 8 * n * px);
    let gather = BatchGather::new(&ctx).unwrap();
    for it in [2u32, 0] {
        ctx.submit_and_wait(|rec| {
            gather.record(
                rec,
                shape,
                it,
                BatchBuffers {
                    views: images.whole(),
                    schedule: sched.whole(),
                    view_rotations: tab.whole(),
                    input: input.whole(),
                    targets: targets.whole(),
                    rotations: rotations.whole(),
                    target_images: target_images.whole(),
                },
            )
        })
        .unwrap();
        let want = batch::cpu::gather(staged_bytes, &schedule, &table, shape, it);
        // The staged pair of each entry is its object's views a and b in the dataset.
        let view_bytes = 4 * shape.pixels as usize;
        for e in &schedule[it as usize * n..(it as usize + 1) * n] {
            for (j, v) in [e[1], e[2]].into_iter().enumerate() {
                let at = (e[0] * shape.views + v) as usize * view_bytes;
                let slot = (2 * e[3] as usize + j) * view_bytes;
                assert_eq!(
                    &staged_bytes[slot..slot + view_bytes],
                    &bytes[at..at + view_bytes]
                );
            }
        }
        let (i, t, rot) = (&want.input, &want.targets, &want.rotations);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let got_i: Vec<f32> = ctx.read_buffer(&input, 0, 4 * n * px).unwrap();
        let got_t: Vec<f32> = ctx.read_buffer(&targets, 0, 2 * n * px).unwrap();
        let got_r: Vec<[f32; 2]> = ctx.read_buffer(&rotations, 0, 2 * n).unwrap();
        assert_eq!(bits(&got_i), bits(i), "input, iteration {it}");
        assert_eq!(bits(&got_t), bits(t), "targets, iteration {it}");
        assert_eq!(&got_r, rot, "rotations, iteration {it}");
        let got_rgba: Vec<[f32; 4]> = ctx.read_buffer(&target_images, 0, 2 * n * px).unwrap();
        let flat = |v: &[[f32; 4]]| bits(&v.iter().flatten().copied().collect::<Vec<_>>());
        assert_eq!(
            flat(&got_rgba),
            flat(&want.target_images),
            "target images, iteration {it}"
        );
    }
}

#[test]
fn a_turned_object_seen_from_azimuth_zero_is_the_object_seen_from_the_view() {
    let Some(ctx) = gpu() else { return };
    // An asymmetric object: the demo target, squashed and shifted.
    let mut mesh = softvk::fit::mesh_fit::demo_target();
    for p in &mut mesh.positions {
        *p = [0.9 * p[0] + 0.08, 0.6 * p[1], 0.5 * p[2] - 0.05];
    }
    let settings = RasterSettings {
        width: 32,
        height: 32,
        ..RasterSettings::default()
    };
    let renderer = Renderer::new(&ctx).unwrap();
    let camera = |az: f64| {
        let mut c = Camera::from_angles(2.732, 30.0, az);
        c.projection = softvk::camera::Projection::Perspective {
            viewing_angle_deg: 15.0,
        };
        c
    };
    let method = Method::Tiled { tile: 8 };
    for view in [1u32, 7, 13, 20] {
        let az = -15.0 * f64::from(view);
        let direct = renderer
            .render_silhouettes(&ctx, &mesh, &[camera(az)], &settings, method)
            .unwrap();
        let [c, s] = view_rotation(az);
        let mut turned = mesh.clone();
        for p in &mut turned.positions {
            *p = [c * p[0] + s * p[2], p[1], c * p[2] - s * p[0]];
        }
        let via_turn = renderer
            .render_silhouettes(&ctx, &turned, &[camera(0.0)], &settings, method)
            .unwrap();
        let worst = direct
            .iter()
            .zip(&via_turn)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        let covered = direct.iter().filter(|&&a| a > 0.5).count();
        assert!(covered > 20, "view {view}: the object is off screen");
        assert!(worst < 1e-3, "view {view}: alpha differs by {worst}");
    }
}

#[test]
fn the_colour_generator_refuses_images_off_its_cells_and_heads_that_do_not_fit() {
    let Some(ctx) = gpu() else { return };
    let t = template();
    for image in [0, 30] {
        let e = MeshDecoder::new(&ctx, &t.positions, image).err().unwrap();
        assert!(
            matches!(e, softvk::Error::Input(ref m) if m.contains("multiple of 4")),
            "{e}"
        );
    }
    let generator = colors::ColorGenerator::new(&ctx, 10, 8).unwrap();
    let own = generator.outputs_per_object() as u32;
    assert_eq!(own, 8 * (4 + 10));
    let mk = |floats: u64| {
        ctx.create_buffer("scratch", 4 * floats, MemoryKind::Device)
            .unwrap()
    };
    let (outputs, images, pooled, palette, colors) = (
        mk(u64::from(own) + 2),
        mk(4 * 64),
        mk(generator.pooled_floats(1)),
        mk(generator.palette_floats(1)),
        mk(4 * 10),
    );
    let head = |offset| colors::HeadLayout {
        stride: own + 2,
        offset,
    };
    let record = |offset| {
        ctx.submit_and_wait(|rec| {
            generator.record_forward(
                rec,
                1,
                1,
                head(offset),
                outputs.whole(),
                images.whole(),
                pooled.whole(),
                palette.whole(),
                colors.whole(),
            )
        })
    };
    record(2).unwrap();
    let e = record(3).unwrap_err();
    assert!(
        matches!(e, softvk::Error::Input(ref m) if m.contains("do not fit")),
        "{e}"
    );
}
