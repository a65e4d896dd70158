//! Reading a `trajectory.csv` back: one row per agent and step, every value a number (`NaN` and
//! `inf` included, as a diverged step writes them). Used by the tests and by scripts built on the
//! library; the figures have their own column-oriented loader (`plot::data`).

use crate::csv::Column;
use std::path::Path;

/// Why a `trajectory.csv` cannot be read back.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// The file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: std::path::PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The file's text is no trajectory (the file and what is wrong).
    #[error("{}: {source}", path.display())]
    In {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        source: Box<TableError>,
    },
    /// No header line.
    #[error("empty file: no header")]
    Empty,
    /// A value that is no number (line 1-based).
    #[error("line {line}: column {column}: not a number: '{value}'")]
    NotANumber {
        /// The line, 1-based.
        line: usize,
        /// The column's name.
        column: String,
        /// The text.
        value: String,
    },
    /// A row with another count of values than the header (line 1-based).
    #[error("line {line}: {values} values for {columns} columns")]
    Width {
        /// The line, 1-based.
        line: usize,
        /// Its values.
        values: usize,
        /// The header's columns.
        columns: usize,
    },
}

/// A `trajectory.csv`, parsed.
#[derive(Debug, Clone)]
pub struct Trajectory {
    header: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Trajectory {
    /// Reads and parses `path`; the error names the file, the line and the column.
    pub fn read(path: &Path) -> Result<Trajectory, TableError> {
        let text = std::fs::read_to_string(path).map_err(|source| TableError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Trajectory::parse(&text).map_err(|e| TableError::In {
            path: path.to_path_buf(),
            source: Box::new(e),
        })
    }

    /// Parses the text of a `trajectory.csv`.
    pub fn parse(text: &str) -> Result<Trajectory, TableError> {
        let mut lines = text.lines();
        let header: Vec<String> = lines
            .next()
            .ok_or(TableError::Empty)?
            .split(',')
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for (n, line) in lines.enumerate() {
            let row: Vec<f64> = line
                .split(',')
                .enumerate()
                .map(|(c, v)| {
                    v.parse::<f64>().map_err(|_| TableError::NotANumber {
                        line: n + 2,
                        column: header[c.min(header.len() - 1)].clone(),
                        value: v.to_string(),
                    })
                })
                .collect::<Result<_, _>>()?;
            if row.len() != header.len() {
                return Err(TableError::Width {
                    line: n + 2,
                    values: row.len(),
                    columns: header.len(),
                });
            }
            rows.push(row);
        }
        Ok(Trajectory { header, rows })
    }

    /// The index of column `c`, if the file has it.
    pub fn column(&self, c: Column) -> Option<usize> {
        self.header.iter().position(|h| h == c.name())
    }

    /// Every row, in file order.
    pub fn rows(&self) -> &[Vec<f64>] {
        &self.rows
    }

    /// The rows of agent `id` (1-based, as in the `agent` column), in step order.
    pub fn agent(&self, id: u32) -> impl Iterator<Item = &[f64]> + '_ {
        let c = self.column(Column::Agent).unwrap_or(usize::MAX);
        self.rows
            .iter()
            .filter(move |r| r.get(c) == Some(&f64::from(id)))
            .map(Vec::as_slice)
    }

    /// Value of column `c` in `row` (NaN when the file has no such column).
    pub fn value(&self, row: &[f64], c: Column) -> f64 {
        self.column(c).map_or(f64::NAN, |i| row[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_of_an_agent_and_their_values_are_found_by_column_name() {
        let t =
            Trajectory::parse("step,t,agent,px\n0,0,1,0.5\n0,0,2,NaN\n1,0.001,1,inf\n").unwrap();
        let a1: Vec<&[f64]> = t.agent(1).collect();
        assert_eq!(a1.len(), 2);
        assert_eq!(t.value(a1[0], Column::Px), 0.5);
        assert!(t.value(a1[1], Column::Px).is_infinite());
        assert!(t.value(t.agent(2).next().unwrap(), Column::Px).is_nan());
        assert!(t.value(a1[0], Column::Py).is_nan());
    }

    #[test]
    fn a_short_row_or_a_word_is_refused_naming_its_line() {
        let e = Trajectory::parse("a,b\n1,2\n3\n").unwrap_err().to_string();
        assert!(e.contains("line 3"), "{e}");
        let e = Trajectory::parse("a,b\n1,x\n").unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("column b"), "{e}");
    }
}
