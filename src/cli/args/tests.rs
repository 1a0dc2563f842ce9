//! The shared flag groups against the library's defaults and checks.

use super::*;
use clap::Parser;
use softvk::lighting::{Directional, Lighting};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};

#[derive(Parser, Debug)]
struct Both {
    #[command(flatten)]
    view: ViewArgs,
    #[command(flatten)]
    raster: RasterArgs,
}

fn parse(args: &[&str]) -> std::result::Result<Both, clap::Error> {
    Both::try_parse_from(std::iter::once("t").chain(args.iter().copied()))
}

#[test]
fn triples_take_exactly_three_finite_numbers() {
    assert_eq!(triple("1,-2.5, 3e-1"), Ok([1.0, -2.5, 0.3]));
    assert_eq!(triple(" 0 , 0 , 0 "), Ok([0.0; 3]));
    for bad in [
        "1,2", "1,2,3,4", "", "1,,3", "a,b,c", "nan,0,0", "0,inf,0", "0,0,-inf",
    ] {
        let err = triple(bad).unwrap_err();
        assert!(!err.contains('\n'), "{err}");
    }
    assert!(triple("1,2").unwrap_err().contains("three"));
    assert!(triple("nan,0,0").unwrap_err().contains("finite"));
}

#[test]
fn numbers_reject_nan_inf_and_out_of_domain_values() {
    assert_eq!(finite("-3"), Ok(-3.0));
    assert!(finite("NaN").is_err() && finite("inf").is_err() && finite("x").is_err());
    assert!(positive("0").is_err() && positive("-1e-9").is_err());
    assert_eq!(positive("1e-9"), Ok(1e-9));
    assert!(non_negative("-0.1").is_err());
    assert_eq!(non_negative("0"), Ok(0.0));
    assert!(viewing_angle("0").is_err() && viewing_angle("90").is_err());
    assert_eq!(viewing_angle("45"), Ok(45.0));
}

#[test]
fn no_flags_give_the_library_defaults() {
    let b = parse(&[]).unwrap();
    assert_eq!(b.view, ViewArgs::default());
    assert_eq!(b.raster, RasterArgs::default());
    assert_eq!(b.view.size(), (256, 256));
    assert_eq!(b.view.camera().unwrap(), Camera::default());
    assert_eq!(
        b.raster.settings(b.view.size()).unwrap(),
        RasterSettings::default()
    );
    assert_eq!(b.raster.lighting(), Lighting::default());
}

#[test]
fn every_flag_reaches_its_setting() {
    let b = parse(&[
        "--width",
        "40",
        "--height",
        "24",
        "--eye",
        "1,-2,3",
        "--viewing-angle",
        "25",
        "--sigma",
        "1e-3",
        "--gamma",
        "0.02",
        "--dist",
        "barycentric",
        "--rgb",
        "hard",
        "--alpha",
        "sum",
        "--near",
        "-0.5",
        "--far",
        "7",
        "--background",
        "0.1,0.2,-0.3",
        "--single-sided",
        "--antialias",
        "--texture-res",
        "4",
        "--vertex-colors",
        "--ambient",
        "0.25",
        "--directional",
        "0.75",
        "--light-dir",
        "-1,0.5,2",
    ])
    .unwrap();
    assert_eq!(b.view.size(), (40, 24));
    assert_eq!(
        b.view.camera().unwrap(),
        Camera {
            eye: DVec3::new(1.0, -2.0, 3.0),
            projection: Projection::Perspective {
                viewing_angle_deg: 25.0
            },
            ..Camera::default()
        }
    );
    assert_eq!(
        b.raster.settings((40, 24)).unwrap(),
        RasterSettings {
            width: 40,
            height: 24,
            sigma: 1e-3,
            gamma: 0.02,
            near: -0.5,
            far: 7.0,
            dist: Dist::Barycentric,
            rgb: Rgb::Hard,
            alpha: Alpha::Sum,
            background: [0.1, 0.2, -0.3],
            double_sided: false,
            antialias: true,
            color_mode: ColorMode::Vertex,
            ..RasterSettings::default()
        }
    );
    assert_eq!(b.raster.texture_res, 4);
    assert_eq!(
        b.raster.lighting(),
        Lighting {
            ambient_intensity: 0.25,
            ambient_color: [1.0; 3],
            directionals: vec![Directional {
                intensity: 0.75,
                color: [1.0; 3],
                direction: [-1.0, 0.5, 2.0],
            }],
        }
    );

    let b = parse(&[
        "--size",
        "9",
        "--distance",
        "3",
        "--elevation",
        "-20",
        "--azimuth",
        "135",
        "--orthographic",
        "--scale",
        "0.5",
    ])
    .unwrap();
    assert_eq!(b.view.size(), (9, 9));
    assert_eq!(
        b.view.camera().unwrap(),
        Camera {
            projection: Projection::Orthographic { scale: 0.5 },
            ..Camera::from_angles(3.0, -20.0, 135.0)
        }
    );
}

#[test]
fn exclusive_and_paired_flags_are_usage_errors() {
    for bad in [
        &["--size", "8", "--width", "8", "--height", "8"][..],
        &["--width", "8"],
        &["--height", "8"],
        &["--eye", "0,0,-3", "--distance", "3"],
        &["--eye", "0,0,-3", "--azimuth", "10"],
        &["--scale", "2"],
        &["--orthographic", "--viewing-angle", "20"],
        &["--size", "0"],
        &["--size", "100000"],
        &["--texture-res", "0"],
        &["--texture-res", "65"],
        &["--sigma", "0"],
        &["--gamma", "-1"],
        &["--dist", "manhattan"],
        &["--rgb", "max"],
        &["--alpha", "min"],
        &["--background", "1,1"],
        &["--light-dir", "nan,1,0"],
        &["--ambient", "-1"],
        &["--near", "inf"],
    ] {
        assert!(parse(bad).is_err(), "{bad:?} was accepted");
    }
    // Negative numbers are values, not flags.
    assert!(parse(&["--azimuth", "-45", "--elevation", "-1e1"]).is_ok());
    assert!(parse(&["--eye", "-1,-1,-1"]).is_ok());
}

#[test]
fn cross_flag_checks_are_errors_not_images() {
    let b = parse(&["--near", "5", "--far", "5"]).unwrap();
    assert!(b.raster.settings((8, 8)).is_err());
    for eye in ["0,0,0", "0,2,0", "0,-1e-3,0"] {
        let b = parse(&["--eye", eye]).unwrap();
        assert!(b.view.camera().is_err(), "{eye}");
    }
    let b = parse(&["--elevation", "90"]).unwrap();
    assert!(b.view.camera().is_err());
    let b = parse(&["--distance", "0"]).unwrap();
    assert!(b.view.camera().is_err());
}
