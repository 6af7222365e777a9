//! Reading an ArduPilot DataFlash log exported one gzipped CSV per message type
//! (`<TYPE>.csv.gz`, a header of ArduPilot field names, `TimeUS` first), with a typed error that
//! names the file and the line for a missing file, a missing column, a value that is not a finite
//! number, or a time that goes backwards.

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;

/// What went wrong reading the log. Lines are counted from 1 with the header as line 1.
#[derive(Debug)]
pub enum LogError {
    /// A file the example needs is not in the folder.
    Missing { file: PathBuf },
    /// The file could not be read or decompressed.
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    /// The header has no such column.
    Column { file: PathBuf, column: String },
    /// A value is empty, not a number, or not finite (NaN, inf).
    Value {
        file: PathBuf,
        line: usize,
        column: String,
        text: String,
    },
    /// `TimeUS` is smaller than on the line before.
    Backwards {
        file: PathBuf,
        line: usize,
        time_us: f64,
        previous_us: f64,
    },
    /// The file has no rows of what the example needs (e.g. no 3-D GPS fix, no IMU 0).
    Empty { file: PathBuf, what: String },
    /// The recording does not allow the run (e.g. the vehicle moves during the alignment).
    Recording { file: PathBuf, what: String },
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Missing { file } => write!(f, "{}: file not found", file.display()),
            Self::Io { file, source } => write!(f, "{}: {source}", file.display()),
            Self::Column { file, column } => {
                write!(f, "{}: no column `{column}` in the header", file.display())
            }
            Self::Value {
                file,
                line,
                column,
                text,
            } => write!(
                f,
                "{} line {line}: column `{column}` is `{text}`, not a finite number",
                file.display()
            ),
            Self::Backwards {
                file,
                line,
                time_us,
                previous_us,
            } => write!(
                f,
                "{} line {line}: TimeUS {time_us} goes back from {previous_us} on the line before",
                file.display()
            ),
            Self::Empty { file, what } => write!(f, "{}: no {what}", file.display()),
            Self::Recording { file, what } => write!(f, "{}: {what}", file.display()),
        }
    }
}

impl std::error::Error for LogError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// The requested numeric columns of one message type, in the order asked for, with the line
/// number of each row (for messages about it).
#[derive(Clone, Debug)]
pub struct Table {
    pub file: PathBuf,
    pub rows: Vec<Vec<f64>>,
    pub lines: Vec<usize>,
}

impl Table {
    /// The rows whose column `c` equals `value` (an instance `I` or core `C`).
    pub fn select(&self, c: usize, value: f64) -> Table {
        let keep: Vec<usize> = (0..self.rows.len())
            .filter(|&i| self.rows[i][c] == value)
            .collect();
        Table {
            file: self.file.clone(),
            rows: keep.iter().map(|&i| self.rows[i].clone()).collect(),
            lines: keep.iter().map(|&i| self.lines[i]).collect(),
        }
    }

    /// An [`LogError::Empty`] unless there is at least one row.
    pub fn non_empty(self, what: &str) -> Result<Self, LogError> {
        if self.rows.is_empty() {
            return Err(LogError::Empty {
                file: self.file,
                what: what.to_owned(),
            });
        }
        Ok(self)
    }
}

/// The path of message type `name` in `dir`.
pub fn path(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}.csv.gz"))
}

fn lines(file: &Path) -> Result<impl Iterator<Item = Result<String, LogError>>, LogError> {
    let handle = File::open(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => LogError::Missing {
            file: file.to_owned(),
        },
        _ => LogError::Io {
            file: file.to_owned(),
            source: e,
        },
    })?;
    let owned = file.to_owned();
    Ok(BufReader::new(MultiGzDecoder::new(handle))
        .lines()
        .map(move |l| {
            l.map_err(|e| LogError::Io {
                file: owned.clone(),
                source: e,
            })
        }))
}

/// Reads `columns` of `dir/<name>.csv.gz` (the first must be `TimeUS`): every value finite,
/// `TimeUS` never decreasing.
pub fn read_table(dir: &Path, name: &str, columns: &[&str]) -> Result<Table, LogError> {
    let file = path(dir, name);
    let mut it = lines(&file)?;
    let header = it.next().transpose()?.unwrap_or_default();
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let index = columns
        .iter()
        .map(|c| {
            names
                .iter()
                .position(|n| n == c)
                .ok_or_else(|| LogError::Column {
                    file: file.clone(),
                    column: (*c).to_owned(),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (mut rows, mut numbers) = (Vec::new(), Vec::new());
    let mut previous = f64::NEG_INFINITY;
    for (k, line) in it.enumerate() {
        let line = line?;
        let number = k + 2;
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').collect();
        let row = index
            .iter()
            .zip(columns)
            .map(|(&i, c)| {
                let text = cells.get(i).copied().unwrap_or("").trim();
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(LogError::Value {
                        file: file.clone(),
                        line: number,
                        column: (*c).to_owned(),
                        text: text.to_owned(),
                    }),
                }
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if row[0] < previous {
            return Err(LogError::Backwards {
                file: file.clone(),
                line: number,
                time_us: row[0],
                previous_us: previous,
            });
        }
        previous = row[0];
        rows.push(row);
        numbers.push(number);
    }
    Ok(Table {
        file,
        rows,
        lines: numbers,
    })
}

/// The parameters of `dir/PARM.csv.gz` (`Name`, `Value`; the last value of a name wins), or
/// `None` if the log has no PARM file.
pub fn read_parameters(dir: &Path) -> Result<Option<HashMap<String, f64>>, LogError> {
    let file = path(dir, "PARM");
    let mut it = match lines(&file) {
        Ok(it) => it,
        Err(LogError::Missing { .. }) => return Ok(None),
        Err(e) => return Err(e),
    };
    let header = it.next().transpose()?.unwrap_or_default();
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let column = |c: &str| {
        names
            .iter()
            .position(|n| *n == c)
            .ok_or_else(|| LogError::Column {
                file: file.clone(),
                column: c.to_owned(),
            })
    };
    let (name, value) = (column("Name")?, column("Value")?);
    let mut out = HashMap::new();
    for (k, line) in it.enumerate() {
        let line = line?;
        let cells: Vec<&str> = line.split(',').collect();
        let (Some(n), Some(v)) = (cells.get(name), cells.get(value)) else {
            continue;
        };
        let parsed = v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        let v = parsed.ok_or_else(|| LogError::Value {
            file: file.clone(),
            line: k + 2,
            column: "Value".to_owned(),
            text: v.trim().to_owned(),
        })?;
        out.insert(n.trim().to_owned(), v);
    }
    Ok(Some(out))
}

/// Writes `text` to `dir/<name>.csv.gz` (the tests' bad recordings).
pub fn write_gz(dir: &Path, name: &str, text: &str) -> std::io::Result<()> {
    let mut encoder = GzEncoder::new(File::create(path(dir, name))?, Compression::fast());
    encoder.write_all(text.as_bytes())?;
    encoder.finish()?;
    Ok(())
}
