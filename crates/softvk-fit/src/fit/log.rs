//! A fit's log row, said once: the row shows its columns (each a name and a value) to a
//! [`Columns`] visitor in [`LogRow::columns`], and everything that stores or prints a log
//! follows from that one function:
//!
//! - the checkpoint's log ([`write_log`] / [`read_log`]): the columns' names and kinds, then
//!   the rows; a checkpoint whose columns are not the row's is refused with one line naming
//!   both lists;
//! - `loss.csv` ([`csv`]): a header of the names, then a line a row, every value in its
//!   shortest round-trip form, except wall time (a column named `seconds`), to the millisecond;
//! - the curves of `loss.png` ([`column()`]).
//!
//! A list column ([`Columns::f64s`]: the articulated fit's angles, one per joint) is one
//! column of the checkpoint (its length, then its values) and `name_0, name_1, …` in the CSV.
//!
//! A visitor rather than a derive: the rows are a handful of numbers each, and one function of
//! plain calls reads as the table it describes.

use std::fmt::Write as _;

use super::checkpoint::{Reader, Writer};
use crate::error::{Error, Result};

/// What a column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A `u32` (the iteration).
    U32 = 1,
    /// A `u64` (a count).
    U64 = 2,
    /// An `f32` (a loss read from the device).
    F32 = 3,
    /// An `f64`.
    F64 = 4,
    /// A list of `f64` (one per joint).
    F64s = 5,
}

impl Kind {
    fn from_code(code: u8) -> Option<Kind> {
        [Kind::U32, Kind::U64, Kind::F32, Kind::F64, Kind::F64s]
            .into_iter()
            .find(|k| *k as u8 == code)
    }
}

/// A log row's column.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Column {
    /// Its name (`loss.csv`'s header).
    pub name: String,
    /// What it holds.
    pub kind: Kind,
}

/// What a row shows its columns to, one call a column in the row's order, each with its name
/// and its value: a visitor that stores the row reads the value, one that loads it writes it.
pub trait Columns {
    /// A `u32` column.
    fn u32(&mut self, name: &str, value: &mut u32);
    /// A `u64` column.
    fn u64(&mut self, name: &str, value: &mut u64);
    /// An `f32` column.
    fn f32(&mut self, name: &str, value: &mut f32);
    /// An `f64` column.
    fn f64(&mut self, name: &str, value: &mut f64);
    /// A list of `f64`, of at most [`MAX_LIST`] values.
    fn f64s(&mut self, name: &str, values: &mut Vec<f64>);
}

/// The longest list column a checkpoint is believed to hold.
pub const MAX_LIST: usize = 4096;

/// A log row a session keeps and a checkpoint carries: one per logged iteration (or, for the
/// pose fits, per iteration).
///
/// Its [`Default`] is the row a checkpoint's values are loaded into (list columns empty).
pub trait LogRow: Clone + Default {
    /// The iteration it logs (from 1).
    fn iteration(&self) -> u32;
    /// The loss the stopping rule watches (the fit's total).
    fn loss(&self) -> f64;
    /// Shows every column to `c`, in order, the iteration first.
    fn columns(&mut self, c: &mut dyn Columns);
}

/// The columns of `row`, list columns as one.
pub fn columns_of<R: LogRow>(row: &R) -> Vec<Column> {
    struct Names(Vec<Column>);
    impl Names {
        fn push(&mut self, name: &str, kind: Kind) {
            self.0.push(Column {
                name: name.into(),
                kind,
            });
        }
    }
    impl Columns for Names {
        fn u32(&mut self, name: &str, _: &mut u32) {
            self.push(name, Kind::U32);
        }
        fn u64(&mut self, name: &str, _: &mut u64) {
            self.push(name, Kind::U64);
        }
        fn f32(&mut self, name: &str, _: &mut f32) {
            self.push(name, Kind::F32);
        }
        fn f64(&mut self, name: &str, _: &mut f64) {
            self.push(name, Kind::F64);
        }
        fn f64s(&mut self, name: &str, _: &mut Vec<f64>) {
            self.push(name, Kind::F64s);
        }
    }
    let mut names = Names(Vec::new());
    row.clone().columns(&mut names);
    names.0
}

/// Appends `log` to a checkpoint: its columns (u32 count, then each name as u32 length +
/// UTF-8 and its kind as a byte), then the rows (u32 count, then each row's values in column
/// order, a list as its u32 length and its values).
pub fn write_log<R: LogRow>(w: &mut Writer, log: &[R]) {
    struct Store<'w>(&'w mut Writer);
    impl Columns for Store<'_> {
        fn u32(&mut self, _: &str, v: &mut u32) {
            self.0.u32(*v);
        }
        fn u64(&mut self, _: &str, v: &mut u64) {
            self.0.u64(*v);
        }
        fn f32(&mut self, _: &str, v: &mut f32) {
            self.0.f32(*v);
        }
        fn f64(&mut self, _: &str, v: &mut f64) {
            self.0.f64(*v);
        }
        fn f64s(&mut self, _: &str, v: &mut Vec<f64>) {
            self.0.u32(v.len() as u32);
            for x in v {
                self.0.f64(*x);
            }
        }
    }
    let columns = columns_of(&R::default());
    w.u32(columns.len() as u32);
    for c in &columns {
        w.u32(c.name.len() as u32);
        w.bytes(c.name.as_bytes());
        w.bytes(&[c.kind as u8]);
    }
    w.u32(log.len() as u32);
    for row in log {
        row.clone().columns(&mut Store(w));
    }
}

/// Reads what [`write_log`] wrote, of at most `max_rows` rows; refuses columns other than the
/// row's (a checkpoint of an earlier softvk whose rows had other columns) in one line.
pub fn read_log<R: LogRow>(r: &mut Reader<'_>, max_rows: u32) -> Result<Vec<R>> {
    let expected = columns_of(&R::default());
    let n = r.u32()?;
    if n as usize > expected.len() {
        return Err(other_columns(&expected, &format!("{n} columns")));
    }
    let mut found = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let len = r.u32()? as usize;
        if len > 256 {
            return Err(Error::Input(
                "checkpoint log: a column name too long".into(),
            ));
        }
        let name = String::from_utf8_lossy(r.take(len)?).into_owned();
        let code = r.take(1)?[0];
        let kind = Kind::from_code(code)
            .ok_or_else(|| Error::Input(format!("checkpoint log: unknown column kind {code}")))?;
        found.push(Column { name, kind });
    }
    if found != expected {
        let names: Vec<&str> = found.iter().map(|c| c.name.as_str()).collect();
        return Err(other_columns(&expected, &names.join(", ")));
    }
    let rows = r.u32()?;
    if rows > max_rows {
        return Err(Error::Input(format!(
            "checkpoint log of {rows} rows, at most {max_rows} expected"
        )));
    }
    struct Load<'a, 'b> {
        r: &'a mut Reader<'b>,
        error: Option<Error>,
    }
    impl<'b> Load<'_, 'b> {
        fn read<T>(&mut self, read: impl FnOnce(&mut Reader<'b>) -> Result<T>, to: &mut T) {
            if self.error.is_none() {
                match read(self.r) {
                    Ok(v) => *to = v,
                    Err(e) => self.error = Some(e),
                }
            }
        }
    }
    impl Columns for Load<'_, '_> {
        fn u32(&mut self, _: &str, v: &mut u32) {
            self.read(Reader::u32, v);
        }
        fn u64(&mut self, _: &str, v: &mut u64) {
            self.read(Reader::u64, v);
        }
        fn f32(&mut self, _: &str, v: &mut f32) {
            self.read(Reader::f32, v);
        }
        fn f64(&mut self, _: &str, v: &mut f64) {
            self.read(Reader::f64, v);
        }
        fn f64s(&mut self, name: &str, v: &mut Vec<f64>) {
            let list = |r: &mut Reader<'_>| -> Result<Vec<f64>> {
                let n = r.u32()? as usize;
                if n > MAX_LIST {
                    return Err(Error::Input(format!(
                        "checkpoint log: {n} values of `{name}`, at most {MAX_LIST} expected"
                    )));
                }
                (0..n).map(|_| r.f64()).collect()
            };
            self.read(list, v);
        }
    }
    let mut load = Load { r, error: None };
    let mut log = Vec::with_capacity(rows as usize);
    for _ in 0..rows {
        let mut row = R::default();
        row.columns(&mut load);
        if let Some(e) = load.error.take() {
            return Err(e);
        }
        log.push(row);
    }
    Ok(log)
}

fn other_columns(expected: &[Column], found: &str) -> Error {
    let names: Vec<&str> = expected.iter().map(|c| c.name.as_str()).collect();
    Error::Input(format!(
        "checkpoint log of other columns ({found}) than this softvk's ({}): written by another \
         version; start the fit again",
        names.join(", ")
    ))
}

/// `loss.csv` of `log`: the header (list columns as `name_0, name_1, …`, as many as the first
/// row's list holds), then a line a row; values in their shortest round-trip form, the
/// `seconds` column to the millisecond.
pub fn csv<R: LogRow>(log: &[R]) -> String {
    struct Line {
        header: String,
        values: String,
    }
    impl Line {
        fn cell(&mut self, name: &str, value: std::fmt::Arguments<'_>) {
            if !self.header.is_empty() {
                self.header.push(',');
                self.values.push(',');
            }
            self.header.push_str(name);
            let _ = self.values.write_fmt(value);
        }
    }
    impl Columns for Line {
        fn u32(&mut self, name: &str, v: &mut u32) {
            self.cell(name, format_args!("{v}"));
        }
        fn u64(&mut self, name: &str, v: &mut u64) {
            self.cell(name, format_args!("{v}"));
        }
        fn f32(&mut self, name: &str, v: &mut f32) {
            self.cell(name, format_args!("{v}"));
        }
        fn f64(&mut self, name: &str, v: &mut f64) {
            if name == "seconds" {
                self.cell(name, format_args!("{v:.3}"));
            } else {
                self.cell(name, format_args!("{v}"));
            }
        }
        fn f64s(&mut self, name: &str, v: &mut Vec<f64>) {
            for (i, x) in v.iter().enumerate() {
                self.cell(&format!("{name}_{i}"), format_args!("{x}"));
            }
        }
    }
    let line = |row: &R| {
        let mut l = Line {
            header: String::new(),
            values: String::new(),
        };
        row.clone().columns(&mut l);
        l
    };
    let mut out = line(log.first().unwrap_or(&R::default())).header;
    out.push('\n');
    for row in log {
        out.push_str(&line(row).values);
        out.push('\n');
    }
    out
}

/// One column of a log as numbers: `(iteration, value)` for each row, the column named `name`
/// (an integer or float column; `None` if the row has none of that name).
pub fn column<R: LogRow>(log: &[R], name: &str) -> Option<Vec<(f64, f64)>> {
    struct Pick<'n> {
        name: &'n str,
        value: Option<f64>,
    }
    impl Columns for Pick<'_> {
        fn u32(&mut self, n: &str, v: &mut u32) {
            if n == self.name {
                self.value = Some(f64::from(*v));
            }
        }
        fn u64(&mut self, n: &str, v: &mut u64) {
            if n == self.name {
                self.value = Some(*v as f64);
            }
        }
        fn f32(&mut self, n: &str, v: &mut f32) {
            if n == self.name {
                self.value = Some(f64::from(*v));
            }
        }
        fn f64(&mut self, n: &str, v: &mut f64) {
            if n == self.name {
                self.value = Some(*v);
            }
        }
        fn f64s(&mut self, _: &str, _: &mut Vec<f64>) {}
    }
    log.iter()
        .map(|row| {
            let mut pick = Pick { name, value: None };
            row.clone().columns(&mut pick);
            Some((f64::from(row.iteration()), pick.value?))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Debug, Default, PartialEq)]
    struct Row {
        iteration: u32,
        loss: f32,
        entries: u64,
        angles: Vec<f64>,
        seconds: f64,
    }

    impl LogRow for Row {
        fn iteration(&self) -> u32 {
            self.iteration
        }
        fn loss(&self) -> f64 {
            f64::from(self.loss)
        }
        fn columns(&mut self, c: &mut dyn Columns) {
            c.u32("iteration", &mut self.iteration);
            c.f32("loss", &mut self.loss);
            c.u64("entries", &mut self.entries);
            c.f64s("angle", &mut self.angles);
            c.f64("seconds", &mut self.seconds);
        }
    }

    #[derive(Clone, Debug, Default, PartialEq)]
    struct Other {
        iteration: u32,
        total: f32,
    }

    impl LogRow for Other {
        fn iteration(&self) -> u32 {
            self.iteration
        }
        fn loss(&self) -> f64 {
            f64::from(self.total)
        }
        fn columns(&mut self, c: &mut dyn Columns) {
            c.u32("iteration", &mut self.iteration);
            c.f32("total", &mut self.total);
        }
    }

    fn rows() -> Vec<Row> {
        vec![
            Row {
                iteration: 1,
                loss: 0.1,
                entries: 7,
                angles: vec![0.5, -1.25],
                seconds: 0.012_345,
            },
            Row {
                iteration: 2,
                loss: 1e-9,
                entries: u64::MAX,
                angles: vec![0.25, 3.0],
                seconds: 2.0,
            },
        ]
    }

    #[test]
    fn a_log_comes_back_from_its_checkpoint_bytes_bit_for_bit() {
        let log = rows();
        let mut w = Writer::default();
        write_log(&mut w, &log);
        let mut r = Reader::new(&w.0);
        let back: Vec<Row> = read_log(&mut r, 10).unwrap();
        assert!(r.done());
        assert_eq!(back, log);
        assert_eq!(back[1].loss.to_bits(), log[1].loss.to_bits());
        // Too many rows for the iterations: refused.
        let e = read_log::<Row>(&mut Reader::new(&w.0), 1).unwrap_err();
        assert!(e.to_string().contains("2 rows, at most 1"), "{e}");
        // Cut anywhere: an error, never a panic.
        for cut in 0..w.0.len() {
            assert!(read_log::<Row>(&mut Reader::new(&w.0[..cut]), 10).is_err());
        }
    }

    #[test]
    fn a_log_of_other_columns_is_refused_naming_both() {
        let mut w = Writer::default();
        write_log(
            &mut w,
            &[Other {
                iteration: 1,
                total: 2.0,
            }],
        );
        let e = read_log::<Row>(&mut Reader::new(&w.0), 10).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("(iteration, total)"), "{e}");
        assert!(
            e.contains("(iteration, loss, entries, angle, seconds)"),
            "{e}"
        );
    }

    #[test]
    fn the_csv_follows_the_columns() {
        let text = csv(&rows());
        assert_eq!(
            text,
            "iteration,loss,entries,angle_0,angle_1,seconds\n\
             1,0.1,7,0.5,-1.25,0.012\n\
             2,0.000000001,18446744073709551615,0.25,3,2.000\n"
        );
        assert_eq!(csv::<Other>(&[]), "iteration,total\n");
        assert_eq!(
            column(&rows(), "entries").unwrap(),
            vec![(1.0, 7.0), (2.0, u64::MAX as f64)]
        );
        assert!(column(&rows(), "nothing").is_none());
    }
}
