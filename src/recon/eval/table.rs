//! The table: the baselines' names, one row of scores per class, and the table and the
//! comparison written as text and as CSV.

use super::{BOOTSTRAP_SEED, Comparison, Interval, RESAMPLES, ScoreRow, mean};

/// The baselines' columns, in the order of [`ScoreRow::baselines`], named by what each knows
/// that a single-view network does not.
pub const BASELINES: [&str; 4] = [
    "retrieval (knows view)",
    "retrieval hull (knows view)",
    "mean shape (knows class)",
    "visual hull (24 views)",
];

/// What each of [`BASELINES`] is and knows: the table's legend.
pub const BASELINE_LEGEND: [&str; 4] = [
    "retrieval (knows view): the training object (any class) whose silhouette from the input's \
     own view index best matches the input's; answers with its true voxels. It is told the \
     viewpoint, which the network is not, and returns hollows no silhouette shows.",
    "retrieval hull (knows view): the same retrieved object answered with its visual hull (what \
     its 24 silhouettes can carve): retrieval told the viewpoint, knowing only silhouettes.",
    "mean shape (knows class): the class's mean training occupancy (≥ half the objects), the \
     same answer for every input; it is told the class.",
    "visual hull (24 views): the test object's own hull from its 24 silhouettes, not a method \
     but what silhouettes at these views can decide.",
];

/// Each object's mean of `per_input`, whose inputs are `views` consecutive views per object.
pub fn per_object(per_input: &[f64], views: usize) -> Vec<f64> {
    per_input.chunks(views.max(1)).map(mean).collect()
}

/// The table as text: a column per network (`networks` names them, in the order of
/// [`ScoreRow::networks`]), then the [`BASELINES`]; one row per class (its mean over test
/// objects), then the mean over classes.
pub fn format_table(networks: &[String], rows: &[ScoreRow]) -> String {
    use std::fmt::Write;
    let names: Vec<&str> = networks
        .iter()
        .map(String::as_str)
        .chain(BASELINES)
        .collect();
    let widths: Vec<usize> = names.iter().map(|m| m.chars().count().max(10)).collect();
    let mut s = String::new();
    let _ = write!(s, "{:<22} {:>7}", "class", "inputs");
    for (m, w) in names.iter().zip(&widths) {
        let _ = write!(s, " {m:>w$}");
    }
    s.push('\n');
    let line = |s: &mut String, class: &str, inputs: usize, values: &[f64]| {
        let _ = write!(s, "{class:<22} {inputs:>7}");
        for (r, w) in values.iter().zip(&widths) {
            let _ = write!(s, " {r:>w$.4}");
        }
        s.push('\n');
    };
    let means = column_means(rows);
    for (r, values) in rows.iter().zip(&means) {
        line(&mut s, &r.class, r.inputs, values);
    }
    if !rows.is_empty() {
        let inputs = rows.iter().map(|r| r.inputs).sum::<usize>();
        line(&mut s, "mean", inputs, &means[rows.len()]);
    }
    s
}

/// Each class's mean over objects of each column (networks, then baselines), then the mean of
/// those over classes.
fn column_means(rows: &[ScoreRow]) -> Vec<Vec<f64>> {
    let mut means: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            r.networks
                .iter()
                .chain(&r.baselines)
                .map(|v| mean(v))
                .collect()
        })
        .collect();
    let columns = means.first().map_or(0, Vec::len);
    let overall = (0..columns)
        .map(|k| mean(&means.iter().map(|c| c[k]).collect::<Vec<_>>()))
        .collect();
    means.push(overall);
    means
}

/// The comparison as text: `network − baseline: mean [lo, hi]`, a row per class and network,
/// then the means over classes, a column per baseline.
pub fn format_comparison(networks: &[String], rows: &[ScoreRow], cmp: &Comparison) -> String {
    use std::fmt::Write;
    let cell = |i: &Interval| format!("{:+.3} [{:+.3}, {:+.3}]", i.mean, i.lo, i.hi);
    let nw = networks
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(0)
        .max(7);
    let widths: Vec<usize> = BASELINES
        .iter()
        .map(|b| b.chars().count().max(24))
        .collect();
    let mut s = format!(
        "network − baseline: mean [lo, hi], 95 % paired bootstrap over test objects \
         ({RESAMPLES} resamples within each class, seed {BOOTSTRAP_SEED}; the mean row is the \
         mean of the class means)\n"
    );
    let _ = write!(s, "{:<22} {:<nw$}", "class", "network");
    for (b, w) in BASELINES.iter().zip(&widths) {
        let _ = write!(s, " {b:>w$}");
    }
    s.push('\n');
    let classes = rows.iter().map(|r| r.class.as_str()).chain(["mean"]);
    for (class, per) in classes.zip(cmp.classes.iter().chain([&cmp.mean])) {
        for (name, intervals) in networks.iter().zip(per) {
            let _ = write!(s, "{class:<22} {name:<nw$}");
            for (i, w) in intervals.iter().zip(&widths) {
                let _ = write!(s, " {:>w$}", cell(i));
            }
            s.push('\n');
        }
    }
    if let Some(first) = networks.first().filter(|_| networks.len() > 1) {
        let _ = writeln!(
            s,
            "\nnetwork − {first}: mean [lo, hi], the same bootstrap (the same objects for both)"
        );
        let _ = writeln!(s, "{:<22} {:<nw$} {:>24}", "class", "network", "difference");
        let classes = rows.iter().map(|r| r.class.as_str()).chain(["mean"]);
        for (class, per) in classes.zip(&cmp.versus_first) {
            for (name, i) in networks[1..].iter().zip(per) {
                let _ = writeln!(s, "{class:<22} {name:<nw$} {:>24}", cell(i));
            }
        }
    }
    let fewest = rows.iter().map(|r| r.baselines[0].len()).min();
    if let Some(n) = fewest.filter(|&n| n < 10) {
        let _ = writeln!(
            s,
            "(as few as {n} test objects in a class: a percentile bootstrap over so few \
             understates the spread)"
        );
    }
    s
}

/// The table and the comparison as CSV, a row per value: `class,column,minus,mean,lo,hi`
/// (`minus` empty for a column's own mean IoU, whose `lo` and `hi` are empty; class `mean` for
/// the mean over classes), enough to write the tables again.
pub fn table_csv(networks: &[String], rows: &[ScoreRow], cmp: &Comparison) -> String {
    use std::fmt::Write;
    let quote = |t: &str| format!("\"{}\"", t.replace('"', "\"\""));
    let mut s = String::from("class,column,minus,mean,lo,hi\n");
    let names: Vec<&str> = networks
        .iter()
        .map(String::as_str)
        .chain(BASELINES)
        .collect();
    let classes: Vec<&str> = rows
        .iter()
        .map(|r| r.class.as_str())
        .chain(["mean"])
        .collect();
    for (class, values) in classes.iter().zip(&column_means(rows)) {
        for (name, v) in names.iter().zip(values) {
            let _ = writeln!(s, "{},{},,{v},,", quote(class), quote(name));
        }
    }
    for (class, per) in classes.iter().zip(cmp.classes.iter().chain([&cmp.mean])) {
        for (name, intervals) in networks.iter().zip(per) {
            for (b, i) in BASELINES.iter().zip(intervals) {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{}",
                    quote(class),
                    quote(name),
                    quote(b),
                    i.mean,
                    i.lo,
                    i.hi
                );
            }
        }
    }
    if let Some(first) = networks.first() {
        for (class, per) in classes.iter().zip(&cmp.versus_first) {
            for (name, i) in networks[1..].iter().zip(per) {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{}",
                    quote(class),
                    quote(name),
                    quote(first),
                    i.mean,
                    i.lo,
                    i.hi
                );
            }
        }
    }
    s
}
