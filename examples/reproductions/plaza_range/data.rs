//! Reading a Plaza-style range-only recording: four headerless CSV files, each either plain
//! (`GT.csv`, as in the data set's folder) or gzipped (`GT.csv.gz`, as vendored), with a typed
//! error naming the file and the line for a missing file, a short or non-numeric row, a time
//! going backwards or a reading from a beacon the survey does not list.
//!
//! | file | columns |
//! |---|---|
//! | `GT` | time s, x m, y m, heading rad: the ground-truth path (GPS) |
//! | `DR` | time s, Δdistance m, Δheading rad: wheel-odometry increments over the interval ending at the time |
//! | `TD` | time s, robot id, beacon id, range m: the UWB ranges |
//! | `TL` | beacon id, x m, y m: the surveyed beacons |

use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;

use super::model::MAX_BEACONS;

/// What went wrong reading the recording. Lines are counted from 1 (the files have no header).
#[derive(Debug)]
pub enum DataError {
    /// Neither `<NAME>.csv` nor `<NAME>.csv.gz` is in the folder.
    Missing { file: PathBuf },
    /// The file could not be read or decompressed.
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    /// A row has fewer columns than the file needs.
    Columns {
        file: PathBuf,
        line: usize,
        found: usize,
        expected: usize,
    },
    /// A value is empty, not a number, or not finite (NaN, inf).
    Value {
        file: PathBuf,
        line: usize,
        column: usize,
        text: String,
    },
    /// The time is smaller than on the row before.
    Backwards {
        file: PathBuf,
        line: usize,
        time: f64,
        previous: f64,
    },
    /// A range from a beacon id that `TL` does not list, or a beacon listed twice.
    Beacon {
        file: PathBuf,
        line: usize,
        id: f64,
        what: &'static str,
    },
    /// The file has no rows of what the example needs.
    Empty { file: PathBuf, what: String },
}

impl fmt::Display for DataError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Missing { file } => {
                write!(f, "{}(.gz): file not found", file.display())
            }
            Self::Io { file, source } => write!(f, "{}: {source}", file.display()),
            Self::Columns {
                file,
                line,
                found,
                expected,
            } => write!(
                f,
                "{} line {line}: {found} columns, {expected} expected",
                file.display()
            ),
            Self::Value {
                file,
                line,
                column,
                text,
            } => write!(
                f,
                "{} line {line}: column {column} is `{text}`, not a finite number",
                file.display()
            ),
            Self::Backwards {
                file,
                line,
                time,
                previous,
            } => write!(
                f,
                "{} line {line}: time {time} goes back from {previous} on the line before",
                file.display()
            ),
            Self::Beacon {
                file,
                line,
                id,
                what,
            } => write!(f, "{} line {line}: beacon {id} {what}", file.display()),
            Self::Empty { file, what } => write!(f, "{}: no {what}", file.display()),
        }
    }
}

impl std::error::Error for DataError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// The rows of one file (the first `columns` values of each) and their line numbers.
#[derive(Clone, Debug)]
pub struct Table {
    pub file: PathBuf,
    pub rows: Vec<Vec<f64>>,
    pub lines: Vec<usize>,
}

/// Opens `dir/<name>.csv`, else `dir/<name>.csv.gz`.
fn open(dir: &Path, name: &str) -> Result<(PathBuf, Box<dyn Read>), DataError> {
    let plain = dir.join(format!("{name}.csv"));
    let gz = dir.join(format!("{name}.csv.gz"));
    let io = |file: &Path, e: std::io::Error| DataError::Io {
        file: file.to_owned(),
        source: e,
    };
    match File::open(&plain) {
        Ok(f) => return Ok((plain, Box::new(f))),
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(&plain, e)),
        Err(_) => {}
    }
    match File::open(&gz) {
        Ok(f) => Ok((gz, Box::new(MultiGzDecoder::new(f)))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(DataError::Missing { file: plain })
        }
        Err(e) => Err(io(&gz, e)),
    }
}

/// Reads the first `columns` values of every row of `dir/<name>.csv[.gz]`: all finite and, if
/// `timed`, the first (the time) never decreasing. Blank lines are skipped.
pub fn read(dir: &Path, name: &str, columns: usize, timed: bool) -> Result<Table, DataError> {
    let (file, reader) = open(dir, name)?;
    let (mut rows, mut lines) = (Vec::new(), Vec::new());
    let mut previous = f64::NEG_INFINITY;
    for (k, line) in BufReader::new(reader).lines().enumerate() {
        let number = k + 1;
        let line = line.map_err(|e| DataError::Io {
            file: file.clone(),
            source: e,
        })?;
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() < columns {
            return Err(DataError::Columns {
                file,
                line: number,
                found: cells.len(),
                expected: columns,
            });
        }
        let row = cells[..columns]
            .iter()
            .enumerate()
            .map(|(c, text)| match text.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(DataError::Value {
                    file: file.clone(),
                    line: number,
                    column: c + 1,
                    text: (*text).to_owned(),
                }),
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if timed {
            if row[0] < previous {
                return Err(DataError::Backwards {
                    file,
                    line: number,
                    time: row[0],
                    previous,
                });
            }
            previous = row[0];
        }
        rows.push(row);
        lines.push(number);
    }
    if rows.is_empty() {
        return Err(DataError::Empty {
            file,
            what: "rows".into(),
        });
    }
    Ok(Table { file, rows, lines })
}

/// A surveyed beacon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beacon {
    /// The id the ranges name it by.
    pub id: f64,
    /// Its position [m].
    pub x: f64,
    pub y: f64,
}

/// One UWB range, to the beacon at index `beacon` of [`Recording::beacons`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RangeReading {
    pub t: f64,
    pub beacon: usize,
    pub range: f64,
}

/// One odometry increment over (previous time, `t`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Odometry {
    pub t: f64,
    pub distance: f64,
    pub turn: f64,
}

/// A ground-truth pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    pub t: f64,
    pub x: f64,
    pub y: f64,
    pub heading: f64,
}

/// The four files.
#[derive(Clone, Debug)]
pub struct Recording {
    pub truth: Vec<Truth>,
    pub odometry: Vec<Odometry>,
    pub ranges: Vec<RangeReading>,
    pub beacons: Vec<Beacon>,
    /// The file the ranges came from (for messages about them).
    pub range_file: PathBuf,
    /// Ranges found earlier in time than a row above them (sorted into place).
    pub reordered_ranges: usize,
}

/// Reads `GT`, `DR`, `TD` and `TL` from `dir`: `GT` and `DR` in time order (`DR` strictly, an
/// increment needs an interval), `TD` sorted by time; ranges must name a beacon of `TL` (each
/// listed once, at most [`MAX_BEACONS`]) and be positive.
pub fn load(dir: &Path) -> Result<Recording, DataError> {
    let tl = read(dir, "TL", 3, false)?;
    let mut beacons: Vec<Beacon> = Vec::new();
    for (r, &line) in tl.rows.iter().zip(&tl.lines) {
        if beacons.iter().any(|b| b.id == r[0]) {
            return Err(DataError::Beacon {
                file: tl.file.clone(),
                line,
                id: r[0],
                what: "is listed twice",
            });
        }
        if beacons.len() == MAX_BEACONS {
            return Err(DataError::Beacon {
                file: tl.file.clone(),
                line,
                id: r[0],
                what: "is one more than the example's state has room for (MAX_BEACONS)",
            });
        }
        beacons.push(Beacon {
            id: r[0],
            x: r[1],
            y: r[2],
        });
    }
    let gt = read(dir, "GT", 4, true)?;
    let dr = read(dir, "DR", 3, true)?;
    // Ranges are self-contained rows: they are sorted by time (stably) rather than required in
    // order. The Plaza file is a merge of chunks and steps back in time twice (by 64 s and
    // 50 s), and the readings in the overlaps are distinct and agree with the ground truth.
    let mut td = read(dir, "TD", 4, false)?;
    let mut latest = f64::NEG_INFINITY;
    let reordered = td
        .rows
        .iter()
        .filter(|r| {
            let back = r[0] < latest;
            latest = latest.max(r[0]);
            back
        })
        .count();
    let mut order: Vec<usize> = (0..td.rows.len()).collect();
    order.sort_by(|&a, &b| td.rows[a][0].total_cmp(&td.rows[b][0]));
    td.rows = order.iter().map(|&i| td.rows[i].clone()).collect();
    td.lines = order.iter().map(|&i| td.lines[i]).collect();
    // An odometry increment needs an interval: times strictly increasing.
    for (w, l) in dr.rows.windows(2).zip(&dr.lines[1..]) {
        if w[1][0] == w[0][0] {
            return Err(DataError::Value {
                file: dr.file.clone(),
                line: *l,
                column: 1,
                text: format!(
                    "{} (the time of the line before: an increment over no time)",
                    w[1][0]
                ),
            });
        }
    }
    let mut ranges = Vec::with_capacity(td.rows.len());
    for (r, &line) in td.rows.iter().zip(&td.lines) {
        let beacon =
            beacons
                .iter()
                .position(|b| b.id == r[2])
                .ok_or_else(|| DataError::Beacon {
                    file: td.file.clone(),
                    line,
                    id: r[2],
                    what: "is not in TL (the surveyed beacons)",
                })?;
        if !(r[3] > 0.0) {
            return Err(DataError::Value {
                file: td.file.clone(),
                line,
                column: 4,
                text: format!("{} (a range must be positive)", r[3]),
            });
        }
        ranges.push(RangeReading {
            t: r[0],
            beacon,
            range: r[3],
        });
    }
    Ok(Recording {
        truth: gt
            .rows
            .iter()
            .map(|r| Truth {
                t: r[0],
                x: r[1],
                y: r[2],
                heading: r[3],
            })
            .collect(),
        odometry: dr
            .rows
            .iter()
            .map(|r| Odometry {
                t: r[0],
                distance: r[1],
                turn: r[2],
            })
            .collect(),
        ranges,
        beacons,
        range_file: td.file,
        reordered_ranges: reordered,
    })
}

/// Writes `text` to `dir/<name>.csv` (the tests' bad recordings).
pub fn write_csv(dir: &Path, name: &str, text: &str) -> std::io::Result<()> {
    std::fs::write(dir.join(format!("{name}.csv")), text)
}
