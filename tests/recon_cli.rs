//! The reconstruction commands end to end on a tiny configuration (two classes, a few objects,
//! a narrow network, a few iterations): `softvk dataset`, `train-recon` (twice: the same
//! bytes; and stopped then resumed: the same bytes again), `eval-recon` and `recon`; and the
//! model file's round trip and refusals.

mod common;

use std::path::Path;
use std::process::Output;

use common::{TempDir, softvk};
use softvk::recon::model::{ReconModel, Reconstructor};
use softvk::recon::npz::{self, NpyArray, NpyData};
use softvk::recon::train::NetShape;

fn ok(run: Output, what: &str) -> String {
    assert!(
        run.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8_lossy(&run.stdout).into_owned()
}

fn dataset(dir: &TempDir) -> std::path::PathBuf {
    let out = dir.path("data");
    ok(
        softvk()
            .args(["dataset", "--out", out.to_str().unwrap()])
            .args(["--categories", "chair,car", "--train", "3", "--val", "1"])
            .args(["--test", "1", "--seed", "2"])
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap(),
        "softvk dataset",
    );
    out
}

/// `train-recon` with a tiny network; `extra` flags appended.
fn train(data: &Path, model: &Path, iters: u32, extra: &[&str]) -> String {
    ok(
        softvk()
            .args(["train-recon", "--dataset", data.to_str().unwrap()])
            .args(["--out", model.to_str().unwrap()])
            .args(["--iters", &iters.to_string(), "--batch", "2"])
            .args(["--channels", "2,3,4", "--latent", "8", "--hidden", "8"])
            .args(["--lr", "1e-3", "--log-every", "2", "--val-every", "2"])
            .args(["--val-views", "1"])
            .args(extra)
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap(),
        "softvk train-recon",
    )
}

#[test]
fn train_twice_resume_evaluate_and_reconstruct() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("recon-cli");
    let data = dataset(&dir);
    let (a, b, c) = (dir.path("a.npz"), dir.path("b.npz"), dir.path("c.npz"));
    // c's checkpoints, in its report folder by default.
    let c_train = dir.path("c-train");
    let c_train = c_train.to_str().unwrap();
    let said = train(&data, &a, 4, &[]);
    assert!(said.contains("trained 4 iterations"), "{said}");
    train(&data, &b, 4, &[]);
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    assert!(bytes(&a) == bytes(&b), "a second run wrote other bytes");
    // Stopped after 2 (a finished run of 2), then resumed to 4: the same model.
    train(&data, &c, 2, &[]);
    let said = train(&data, &c, 4, &["--resume", c_train]);
    assert!(
        said.contains("resumed after iteration 2: ran iterations 3..4;"),
        "a resumed run runs only the rest: {said}"
    );
    assert!(bytes(&a) == bytes(&c), "a resumed run differs");
    // Its log is the uninterrupted run's: the checkpoint's rows, then the rest's (a run that
    // started again from 1 would log iterations 2 twice).
    let report_of = |m: &Path, file: &str| {
        let dir = m.with_file_name(format!(
            "{}-train",
            m.file_stem().unwrap().to_str().unwrap()
        ));
        std::fs::read_to_string(dir.join(file)).unwrap()
    };
    assert_eq!(report_of(&c, "loss.csv"), report_of(&a, "loss.csv"));
    // And its validations: the checkpoint's (at 2), then the rest's (at 4).
    assert_eq!(report_of(&c, "val.csv"), report_of(&a, "val.csv"));
    let report = dir.path("a-train");
    let log = std::fs::read_to_string(report.join("loss.csv")).unwrap();
    assert_eq!(
        log.lines().count(),
        3,
        "a header and two submissions:\n{log}"
    );
    let val = std::fs::read_to_string(report.join("val.csv")).unwrap();
    assert_eq!(val.lines().count(), 3, "validations at 2 and 4:\n{val}");
    assert!(report.join("loss.png").exists() && report.join("checkpoint.ckpt").exists());
    // A resume with other options is refused in one line.
    let refused = softvk()
        .args(["train-recon", "--dataset", data.to_str().unwrap()])
        .args(["--out", c.to_str().unwrap(), "--iters", "6", "--batch", "3"])
        .args([
            "--channels",
            "2,3,4",
            "--latent",
            "8",
            "--hidden",
            "8",
            "--resume",
            c_train,
        ])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("other options") && err.lines().count() == 1,
        "{err}"
    );
    // So is a resume with the other recipe (c was trained with SoftRas's, the default).
    let refused = softvk()
        .args(["train-recon", "--dataset", data.to_str().unwrap()])
        .args(["--out", c.to_str().unwrap(), "--iters", "6", "--batch", "2"])
        .args(["--channels", "2,3,4", "--latent", "8", "--hidden", "8"])
        .args(["--lr", "1e-3", "--recipe", "one-view", "--resume", c_train])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("other options"), "{err}");
    // A budget in input images: 9 images at 2 objects × 2 views per iteration (SoftRas's
    // recipe) are 3 iterations; with the one-view recipe, 5.
    for (recipe, said_want) in [
        ("softras", "trained 3 iterations (12 input images)"),
        ("one-view", "trained 5 iterations (10 input images)"),
    ] {
        let said = ok(
            softvk()
                .args(["train-recon", "--dataset", data.to_str().unwrap()])
                .args(["--out", dir.path("img.npz").to_str().unwrap()])
                .args(["--images", "9", "--batch", "2", "--recipe", recipe])
                .args(["--channels", "2,3,4", "--latent", "8", "--hidden", "8"])
                .args(["--val-every", "100"])
                .output()
                .unwrap(),
            "softvk train-recon --images",
        );
        assert!(said.contains(said_want), "{said}");
    }
    // The learning rate's step may be added on resume where it changes no iteration already
    // run (c's checkpoint is at 4: a step at 5 is fine), not where it would have (at 3).
    train(&data, &c, 6, &["--resume", c_train, "--lr-step", "5"]);
    let refused = softvk()
        .args(["train-recon", "--dataset", data.to_str().unwrap()])
        .args(["--out", c.to_str().unwrap(), "--iters", "8", "--batch", "2"])
        .args(["--channels", "2,3,4", "--latent", "8", "--hidden", "8"])
        .args(["--lr", "1e-3", "--lr-step", "3", "--resume", c_train])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("other options"), "{err}");

    let eval_dir = dir.path("eval");
    let table = ok(
        softvk()
            .args(["eval-recon", "--dataset", data.to_str().unwrap()])
            .args(["--model", a.to_str().unwrap(), "--views", "2"])
            .args(["--report", eval_dir.to_str().unwrap()])
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap(),
        "softvk eval-recon",
    );
    let rows: Vec<&str> = table.lines().collect();
    assert!(
        rows[0].contains("a (mesh, parity)")
            && rows[0].contains("a (mesh, winding)")
            && rows[0].contains("retrieval (knows view)"),
        "{table}"
    );
    assert!(
        rows[4].starts_with("mesh predictions voxelized by parity")
            && rows[5].starts_with("mesh predictions voxelized by winding"),
        "{table}"
    );
    assert!(
        rows.iter()
            .any(|r| r.starts_with("baseline retrieval (knows view): ")),
        "{table}"
    );
    assert!(
        rows[1].contains("chair") || rows[2].contains("chair"),
        "{table}"
    );
    assert!(rows[3].starts_with("mean"), "{table}");
    for r in &rows[1..4] {
        let cols: Vec<f64> = r
            .split_whitespace()
            .rev()
            .take(6)
            .map(|c| c.parse().unwrap())
            .collect();
        assert!(cols.iter().all(|v| (0.0..=1.0).contains(v)), "{r}");
    }
    // The differences: a row per class and mean for each of the two columns.
    let at = rows
        .iter()
        .position(|r| r.starts_with("network − baseline"))
        .expect("the comparison");
    // Then, after a blank line, winding against parity (the second column minus the first):
    // a title, a header and a row per class and mean.
    assert_eq!(rows.len(), at + 2 + 3 * 2 + 1 + 2 + 3 + 1, "{table}");
    assert!(rows[at + 2].contains("a (mesh, parity)"), "{table}");
    assert!(
        rows[at + 9].starts_with("network − a (mesh, parity)"),
        "{table}"
    );
    assert!(rows[at + 13].starts_with("mean"), "{table}");
    assert!(
        rows[at + 14].contains("as few as 1 test objects"),
        "{table}"
    );
    assert_eq!(
        std::fs::read_to_string(eval_dir.join("table.txt")).unwrap(),
        table
    );
    let csv = std::fs::read_to_string(eval_dir.join("table.csv")).unwrap();
    // A header, 3 rows (two classes, mean) × 6 columns of means, 3 × 2 × 4 differences from
    // the baselines and 3 of the second column from the first.
    assert_eq!(csv.lines().count(), 1 + 18 + 24 + 3, "{csv}");
    assert!(eval_dir.join("examples.png").exists());
    let input = eval_dir.join("input-03001627-0.png");
    let obj = dir.path("out/chair.obj");
    ok(
        softvk()
            .args(["recon", "--model", a.to_str().unwrap()])
            .args(["--image", input.to_str().unwrap()])
            .args(["--out", obj.to_str().unwrap()])
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap(),
        "softvk recon",
    );
    let text = std::fs::read_to_string(&obj).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 642);
    assert!(dir.path("out/chair-turntable.gif").exists());
    // An image of the wrong size is one clear error.
    let wrong = softvk()
        .args(["recon", "--model", a.to_str().unwrap()])
        .args(["--image", eval_dir.join("examples.png").to_str().unwrap()])
        .args(["--out", dir.path("out/x.obj").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!wrong.status.success());
    let err = String::from_utf8_lossy(&wrong.stderr);
    assert!(
        err.contains("the model takes 64×64") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!dir.path("out/x.obj").exists());
}

/// Writes `<class>_test_predicted_voxels.npz` into `dir`: `arr_0` of `shape` and `data`.
fn write_predictions(dir: &Path, class: &str, shape: Vec<usize>, data: NpyData) {
    std::fs::create_dir_all(dir).unwrap();
    let array = NpyArray::new(shape, data).unwrap();
    npz::write_npz(
        &dir.join(format!("{class}_test_predicted_voxels.npz")),
        &[("arr_0", &array)],
        true,
    )
    .unwrap();
}

/// `eval-recon --predicted LABEL=DIR` scores another program's voxels as a column: the true
/// voxels from every view score 1, an empty grid 0, each with its intervals against the
/// baselines; a missing class file, another shape, dtype or value is one error line and
/// writes no report.
#[test]
fn external_predictions_are_scored_as_a_column_and_bad_ones_refused() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("recon-cli-predicted");
    let data = dir.path("data");
    ok(
        softvk()
            .args(["dataset", "--out", data.to_str().unwrap()])
            .args(["--categories", "chair,car", "--train", "2", "--val", "1"])
            .args(["--test", "2", "--seed", "3"])
            .output()
            .unwrap(),
        "softvk dataset",
    );
    const GRID: usize = 32 * 32 * 32;
    let (chair, car) = ("03001627", "02958343");
    // Chairs predicted perfectly from every view (the truth repeated 24 times), cars empty.
    let truth = |class: &str| {
        let a = npz::read_npz_first(&data.join(format!("{class}_test_voxels.npz"))).unwrap();
        assert_eq!(a.shape, [2, 32, 32, 32]);
        a.to_bools()
    };
    let repeated: Vec<u8> = truth(chair)
        .chunks(GRID)
        .flat_map(|g| std::iter::repeat_n(g, 24).flatten().map(|&x| u8::from(x)))
        .collect();
    let shape = vec![2, 24, 32, 32, 32];
    let good = dir.path("good");
    write_predictions(&good, chair, shape.clone(), NpyData::U8(repeated.clone()));
    write_predictions(
        &good,
        car,
        shape.clone(),
        NpyData::U8(vec![0; 2 * 24 * GRID]),
    );
    let eval = |predicted: &Path, report: &Path| {
        softvk()
            .args(["eval-recon", "--dataset", data.to_str().unwrap()])
            .args(["--predicted", &format!("theirs={}", predicted.display())])
            .args(["--views", "3", "--report", report.to_str().unwrap()])
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap()
    };
    let report = dir.path("report");
    let table = ok(eval(&good, &report), "softvk eval-recon --predicted");
    let rows: Vec<&str> = table.lines().collect();
    assert!(rows[0].contains("theirs (predicted)"), "{table}");
    let first = |class: &str| -> f64 {
        let r = rows.iter().find(|r| r.contains(class)).unwrap();
        r.split_whitespace().nth(3).unwrap().parse().unwrap()
    };
    assert_eq!((first("(chair)"), first("(car)")), (1.0, 0.0), "{table}");
    assert!(
        rows[3].starts_with("mean") && rows[3].contains(" 0.5000 "),
        "{table}"
    );
    // The CSV: each class's difference to retrieval is 1 (or 0) minus retrieval's mean, inside
    // its interval.
    let csv = std::fs::read_to_string(report.join("table.csv")).unwrap();
    let value = |class: &str, column: &str, minus: &str| -> [f64; 3] {
        let start = format!("\"{class}\",\"{column}\",{minus},");
        let line = csv
            .lines()
            .find(|l| l.starts_with(&start))
            .unwrap_or_else(|| panic!("no {start} in\n{csv}"));
        let v: Vec<f64> = line[start.len()..]
            .split(',')
            .map(|c| c.parse().unwrap_or(f64::NAN))
            .collect();
        [v[0], v[1], v[2]]
    };
    let retrieval = "\"retrieval (knows view)\"";
    for (class, ours) in [
        (format!("{chair} (chair)"), 1.0),
        (format!("{car} (car)"), 0.0),
    ] {
        let base = value(&class, "retrieval (knows view)", "")[0];
        let [d, lo, hi] = value(&class, "theirs (predicted)", retrieval);
        assert!(
            (d - (ours - base)).abs() < 1e-12,
            "{class}: {d} vs {ours} − {base}"
        );
        assert!(lo <= d && d <= hi, "{class}: {d} [{lo}, {hi}]");
        assert_eq!(value(&class, "theirs (predicted)", "")[0], ours);
    }
    let [d, lo, hi] = value("mean", "theirs (predicted)", retrieval);
    assert!(lo <= d && d <= hi && lo < hi, "mean: {d} [{lo}, {hi}]");

    // Refusals, each one line naming the file, with no report written.
    let refused = |name: &str, setup: &dyn Fn(&Path), says: &str| {
        let bad = dir.path(name);
        setup(&bad);
        let report = dir.path(&format!("{name}-report"));
        let run = eval(&bad, &report);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{name}: accepted");
        assert!(
            err.lines().count() == 1 && err.contains(says) && err.contains("predicted_voxels"),
            "{name}: {err}"
        );
        assert!(!report.exists(), "{name}: a report was written");
    };
    refused(
        "missing",
        &|d| write_predictions(d, chair, shape.clone(), NpyData::U8(repeated.clone())),
        &format!("no predictions for class {car}"),
    );
    refused(
        "views",
        &|d| {
            write_predictions(d, chair, shape.clone(), NpyData::U8(repeated.clone()));
            write_predictions(
                d,
                car,
                vec![2, 23, 32, 32, 32],
                NpyData::U8(vec![0; 2 * 23 * GRID]),
            );
        },
        "has shape [2, 23, 32, 32, 32], expected [2, 24, 32, 32, 32]",
    );
    refused(
        "dtype",
        &|d| {
            write_predictions(d, chair, shape.clone(), NpyData::U8(repeated.clone()));
            write_predictions(
                d,
                car,
                shape.clone(),
                NpyData::F32(vec![0.0; 2 * 24 * GRID]),
            );
        },
        "is float32, expected uint8",
    );
    refused(
        "values",
        &|d| {
            let mut twos = repeated.clone();
            twos[5] = 2;
            write_predictions(d, chair, shape.clone(), NpyData::U8(twos));
            write_predictions(d, car, shape.clone(), NpyData::U8(vec![0; 2 * 24 * GRID]));
        },
        "holds 2, expected only 0 and 1",
    );
}

/// The `--field` flags of a tiny conditioned field.
const FIELD: [&str; 11] = [
    "--field",
    "--field-layers",
    "2",
    "--field-width",
    "16",
    "--field-freqs",
    "2",
    "--rays",
    "16",
    "--anchors",
    "512",
];

#[test]
fn a_conditioned_field_trains_resumes_and_sits_beside_the_mesh_in_the_table() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("recon-cli-field");
    let data = dataset(&dir);
    let (f, g, mesh) = (dir.path("f.npz"), dir.path("g.npz"), dir.path("m.npz"));
    let said = train(&data, &f, 4, &FIELD);
    assert!(said.contains("trained 4 iterations"), "{said}");
    // Stopped after 2, resumed to 4: the same model, bit for bit.
    train(&data, &g, 2, &FIELD);
    let g_train = dir.path("g-train");
    let resume = ["--resume", g_train.to_str().unwrap()];
    let said = train(&data, &g, 4, &[&FIELD[..], &resume].concat());
    assert!(
        said.contains("resumed after iteration 2: ran iterations 3..4;"),
        "a resumed field run runs only the rest: {said}"
    );
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    assert!(bytes(&f) == bytes(&g), "a resumed field run differs");
    // Its loss log is the uninterrupted run's: the checkpoint's rows, then the rest's.
    let log_of = |m: &Path| {
        let stem = m.file_stem().unwrap().to_str().unwrap();
        std::fs::read_to_string(m.with_file_name(format!("{stem}-train")).join("loss.csv")).unwrap()
    };
    let log = log_of(&f);
    assert_eq!(
        log.lines().count(),
        3,
        "a header and two submissions:\n{log}"
    );
    assert_eq!(log_of(&g), log);
    // A field checkpoint does not resume as a mesh run: another kind of checkpoint.
    let refused = softvk()
        .args(["train-recon", "--dataset", data.to_str().unwrap()])
        .args(["--out", g.to_str().unwrap(), "--iters", "6", "--batch", "2"])
        .args(["--channels", "2,3,4", "--latent", "8", "--hidden", "8"])
        .args(["--lr", "1e-3"])
        .args(resume)
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("a conditioned field training checkpoint, not a mesh network training's")
            && err.lines().count() == 1,
        "{err}"
    );
    train(&data, &mesh, 2, &[]);
    let eval_dir = dir.path("eval");
    let table = ok(
        softvk()
            .args(["eval-recon", "--dataset", data.to_str().unwrap()])
            .args(["--model", mesh.to_str().unwrap()])
            .args(["--model", f.to_str().unwrap(), "--views", "2"])
            .args(["--report", eval_dir.to_str().unwrap()])
            .env("SOFTVK_VALIDATION", "1")
            .output()
            .unwrap(),
        "softvk eval-recon",
    );
    let rows: Vec<&str> = table.lines().collect();
    assert!(
        rows[0].contains("m (mesh, parity)")
            && rows[0].contains("m (mesh, winding)")
            && rows[0].contains("f (field)"),
        "{table}"
    );
    assert!(rows[6].starts_with("field predictions"), "{table}");
    for r in &rows[1..4] {
        let cols: Vec<f64> = r
            .split_whitespace()
            .rev()
            .take(7)
            .map(|c| c.parse().unwrap())
            .collect();
        assert!(cols.iter().all(|v| (0.0..=1.0).contains(v)), "{r}");
    }
    assert!(eval_dir.join("examples.png").exists());
}

/// A conditioned-field model whose field is known whatever the image: the encoder's parameters
/// are zero, so every code (the hidden biases it predicts) is zero, and the MLP (one hidden
/// layer of 4 units, no encoding frequencies) passes the normalised `u_x` through one softplus
/// unit to the logit `slope · softplus(u_x) − 1`. With a slope of 10, φ = 0.5 on the plane
/// `u_x = 0.1` (softplus at β = 100 is within 5e-7 of `u_x` there; x = 0.055 in the field's
/// cube of half-edge 0.55); with a slope of 0, φ = σ(−1) everywhere, and there is no surface.
/// Returns the model's file and a 16×16 input image.
fn plane_field(dir: &TempDir, slope: f32) -> (std::path::PathBuf, std::path::PathBuf) {
    use softvk::field::MlpLayout;
    use softvk::recon::field::FieldNet;
    let shape = FieldNet {
        net: NetShape {
            image: 16,
            channels: [2, 2, 2],
            latent: 4,
            hidden: 4,
        },
        mlp: MlpLayout {
            hidden_layers: 1,
            width: 4,
            frequencies: 0,
        },
    };
    let encoder = shape.encoder_param_count().unwrap() as usize;
    let mut params = vec![0.0f32; shape.param_count().unwrap() as usize];
    let mlp = &mut params[encoder..];
    mlp[0] = 1.0; // hidden unit 0 ← u_x (layer 0's weights are row-major [unit][input])
    let (out, width, _) = shape.mlp.layer(1);
    mlp[out] = slope; // the logit ← hidden unit 0
    mlp[out + width] = -1.0; // the logit's bias
    let model = ReconModel {
        net: shape.net,
        field: Some(shape.mlp),
        params,
        iteration: 0,
    };
    let path = dir.path(&format!("plane-{slope}.npz"));
    model.save(&path).unwrap();
    let image = dir.path("input.png");
    image::RgbaImage::from_pixel(16, 16, image::Rgba([200, 120, 40, 255]))
        .save(&image)
        .unwrap();
    (path, image)
}

fn recon(model: &Path, image: &Path, obj: &Path) -> Output {
    softvk()
        .args(["recon", "--model", model.to_str().unwrap()])
        .args(["--image", image.to_str().unwrap()])
        .args(["--out", obj.to_str().unwrap()])
        .env("SOFTVK_VALIDATION", "1")
        .output()
        .unwrap()
}

/// `recon` meshes a field that crosses φ = 0.5: the OBJ holds the plane x = 0.055 across the
/// field's cube, and the turntable is written beside it.
#[test]
fn recon_meshes_a_field_with_a_surface() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("recon-cli-plane");
    let (model, image) = plane_field(&dir, 10.0);
    let obj = dir.path("out/plane.obj");
    let said = ok(recon(&model, &image, &obj), "softvk recon");
    assert!(said.starts_with("wrote"), "{said}");
    let text = std::fs::read_to_string(&obj).unwrap();
    assert!(text.lines().any(|l| l.starts_with("f ")), "no faces");
    let vertices: Vec<[f64; 3]> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|c| c.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert!(!vertices.is_empty(), "no vertices");
    // Marching cubes interpolates φ linearly along the lattice's edges (0.55 / 32 apart);
    // σ of a logit linear in x is nearly linear over one edge: 1.1e-5 off at most, measured.
    for v in &vertices {
        assert!(
            (v[0] - 0.055).abs() < 1e-4,
            "a vertex off the plane x = 0.055: {v:?}"
        );
    }
    for axis in [1, 2] {
        let (lo, hi) = vertices.iter().fold((f64::MAX, f64::MIN), |(lo, hi), v| {
            (lo.min(v[axis]), hi.max(v[axis]))
        });
        assert!(lo < -0.5 && hi > 0.5, "axis {axis} spans only {lo}..{hi}");
    }
    assert!(dir.path("out/plane-turntable.gif").exists());
}

/// `recon` on a field that never reaches φ = 0.5 is one error line, exit status 1, and writes
/// neither the mesh nor the turntable.
#[test]
fn recon_of_a_field_without_a_surface_is_one_error_and_writes_nothing() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("recon-cli-empty");
    let (model, image) = plane_field(&dir, 0.0);
    let obj = dir.path("out/empty.obj");
    let run = recon(&model, &image, &obj);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert_eq!(
        err.lines().collect::<Vec<_>>(),
        [format!(
            "softvk: error: {}: the field is empty for this image (no φ = 0.5 surface)",
            image.display()
        )],
        "{err}"
    );
    assert!(run.stdout.is_empty());
    assert!(!obj.exists() && !dir.path("out/empty-turntable.gif").exists());
}

#[test]
fn a_model_round_trips_through_its_file_and_bad_files_are_refused() {
    let Some(gpu) = common::gpu() else { return };
    let dir = TempDir::new("recon-model");
    let net = NetShape {
        image: 16,
        channels: [2, 2, 2],
        latent: 4,
        hidden: 4,
    };
    let n = softvk::recon::train::param_count(&net).unwrap() as usize;
    let mut r = common::rng(1);
    use rand::RngExt;
    let params: Vec<f32> = (0..n).map(|_| r.random_range(-0.3f32..0.3)).collect();
    let model = ReconModel {
        net,
        field: None,
        params,
        iteration: 7,
    };
    let path = dir.path("m.npz");
    model.save(&path).unwrap();
    let back = ReconModel::load(&path).unwrap();
    assert_eq!(back, model);
    // Files of format 1 (whose mesh decoder squashed the centroid twice) and 2 (whose colour
    // head regressed colours instead of sampling the image) are refused, by their format.
    for old in [1, 2] {
        use softvk::recon::npz::{self, NpyArray, NpyData, Npz};
        let mut file = Npz::open(&path).unwrap();
        let names: Vec<String> = file.names().iter().map(|n| n.to_string()).collect();
        let mut arrays: Vec<(String, NpyArray)> = names
            .iter()
            .map(|n| (n.clone(), file.array(n).unwrap()))
            .collect();
        for (name, a) in &mut arrays {
            if name == "format" {
                *a = NpyArray::new(vec![1], NpyData::I32(vec![old])).unwrap();
            }
        }
        let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(n, a)| (n.as_str(), a)).collect();
        npz::write_npz(&dir.path("old.npz"), &refs, false).unwrap();
        let e = ReconModel::load(&dir.path("old.npz")).unwrap_err();
        assert!(
            matches!(e, softvk::Error::Input(ref m) if m.contains(&format!("model format [{old}]"))),
            "{e}"
        );
    }
    // The loaded model reconstructs what the saved one does.
    let image: Vec<u8> = (0..4 * 16 * 16).map(|i| (i * 37 % 251) as u8).collect();
    let a = Reconstructor::new(&gpu, &model, 1)
        .unwrap()
        .reconstruct(&gpu, &image)
        .unwrap();
    let b = Reconstructor::new(&gpu, &back, 1)
        .unwrap()
        .reconstruct(&gpu, &image)
        .unwrap();
    assert_eq!(a, b);
    assert_eq!(a[0].positions.len(), 642);
    assert_eq!(a[0].colors.len(), 642);
    // Refusals: a parameter count that does not fit the shape, a non-finite parameter, a file
    // that is not a model.
    let short = ReconModel {
        params: model.params[1..].to_vec(),
        ..model.clone()
    };
    short.save(&dir.path("short.npz")).unwrap();
    let e = ReconModel::load(&dir.path("short.npz")).unwrap_err();
    assert!(
        matches!(e, softvk::Error::Input(ref m) if m.contains("parameters")),
        "{e}"
    );
    let mut nan = model.clone();
    nan.params[3] = f32::NAN;
    nan.save(&dir.path("nan.npz")).unwrap();
    let e = ReconModel::load(&dir.path("nan.npz")).unwrap_err();
    assert!(
        matches!(e, softvk::Error::Input(ref m) if m.contains("parameter 3")),
        "{e}"
    );
    std::fs::write(dir.path("junk.npz"), b"not a zip").unwrap();
    assert!(ReconModel::load(&dir.path("junk.npz")).is_err());
}
