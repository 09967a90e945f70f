//! Text point clouds: CSV or whitespace-separated columns, optional header naming X, Y, Z.
//!
//! Accepted layouts (what CloudCompare, PDAL's writers.text, LAStools' las2txt and spreadsheets
//! write):
//! - a header line naming the columns, in any case, quoted or not, optionally behind a comment
//!   marker: `X,Y,Z,Intensity`, `"X","Y","Z"`, `//X Y Z R G B`, `# x y z`; the X/Y/Z columns
//!   are found by name and other columns are ignored (they may hold anything, e.g. `nan`);
//! - no header: the first three columns are X, Y, Z;
//! - a UTF-8 byte order mark at the start (Windows editors and spreadsheets write one) is skipped;
//! - a leading line holding a single integer (the point count of the PTS format) is skipped, as
//!   are blank lines and `#` or `//` comment lines.
//!
//! The separator is decided once from the first header or data line: comma, else semicolon,
//! else whitespace (runs of spaces/tabs).
//!
//! Text has no header count or bounds, so [`TextReader::open`] streams the file once to count
//! the points, compute the bounds and find any bad line; [`PointReader::fill`] then streams it
//! a second time. Neither pass holds more than one line.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use super::{open_file, Bounds, CloudFormat, CloudInfo, Crs, Point3, PointReader};
use crate::error::{Error, Result};

/// How the columns are separated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sep {
    Comma,
    Semicolon,
    Whitespace,
}

impl Sep {
    fn detect(line: &str) -> Sep {
        if line.contains(',') {
            Sep::Comma
        } else if line.contains(';') {
            Sep::Semicolon
        } else {
            Sep::Whitespace
        }
    }

    fn split(self, line: &str) -> Fields<'_> {
        Fields {
            rest: Some(line),
            sep: self,
        }
    }
}

/// The cleaned fields of a line (an iterator without allocation: it runs once per line).
struct Fields<'a> {
    rest: Option<&'a str>,
    sep: Sep,
}

impl<'a> Iterator for Fields<'a> {
    type Item = &'a str;

    fn next(&mut self) -> Option<&'a str> {
        let rest = self.rest?;
        let ch = match self.sep {
            Sep::Comma => ',',
            Sep::Semicolon => ';',
            Sep::Whitespace => {
                let t = rest.trim_start();
                if t.is_empty() {
                    self.rest = None;
                    return None;
                }
                let end = t.find(char::is_whitespace).unwrap_or(t.len());
                self.rest = Some(&t[end..]);
                return Some(clean(&t[..end]));
            }
        };
        match rest.split_once(ch) {
            Some((field, tail)) => {
                self.rest = Some(tail);
                Some(clean(field))
            }
            None => {
                self.rest = None;
                Some(clean(rest))
            }
        }
    }
}

/// A field without surrounding whitespace and quotes.
fn clean(field: &str) -> &str {
    field.trim().trim_matches(|c| c == '"' || c == '\'').trim()
}

/// Whether the line starts with a comment marker (`//`, `#`), and the line without it
/// (CloudCompare writes its header as `//X,Y,Z,...`).
fn strip_comment(line: &str) -> (bool, &str) {
    let t = line.trim();
    if let Some(rest) = t.strip_prefix("//") {
        (true, rest)
    } else if let Some(rest) = t.strip_prefix('#') {
        (true, rest)
    } else {
        (false, t)
    }
}

/// The layout found at the top of the file.
#[derive(Debug, Clone, Copy)]
struct Layout {
    sep: Sep,
    /// Column indices of X, Y, Z.
    cols: [usize; 3],
    /// 1-based number of the first line that may hold data.
    first_data_line: u64,
}

/// One pass over the file: lines in, points out.
struct Pass {
    path: PathBuf,
    lines: BufReader<File>,
    line: String,
    line_no: u64,
    layout: Layout,
    index: u64,
}

impl Pass {
    fn start(path: &Path, layout: Layout) -> Result<Pass> {
        Ok(Pass {
            path: path.to_path_buf(),
            lines: BufReader::with_capacity(1 << 20, open_file(path)?),
            line: String::new(),
            line_no: 0,
            layout,
            index: 0,
        })
    }

    /// Read the next raw line into `self.line`; false at the end.
    fn next_line(&mut self) -> Result<bool> {
        self.line.clear();
        let n = self.lines.read_line(&mut self.line).map_err(|e| {
            let problem = if e.kind() == std::io::ErrorKind::InvalidData {
                format!(
                    "line {}: not text (invalid UTF-8); not a point cloud",
                    self.line_no + 1
                )
            } else {
                format!("cannot read: {e}")
            };
            Error::input(&self.path, problem)
        })?;
        if n == 0 {
            return Ok(false);
        }
        self.line_no += 1;
        if self.line_no == 1 {
            super::strip_bom(&mut self.line);
        }
        Ok(true)
    }

    /// The next point, or `None` at the end of the file.
    fn next_point(&mut self) -> Result<Option<Point3>> {
        while self.next_line()? {
            if self.line_no < self.layout.first_data_line {
                continue;
            }
            let t = self.line.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with("//") {
                continue;
            }
            let p = parse_row(t, &self.layout).map_err(|problem| {
                Error::input(&self.path, format!("line {}: {problem}", self.line_no))
            })?;
            if !p.iter().all(|v| v.is_finite()) {
                return Err(Error::input(
                    &self.path,
                    format!(
                        "line {}: point {} has a NaN or infinite coordinate",
                        self.line_no, self.index
                    ),
                ));
            }
            self.index += 1;
            return Ok(Some(p));
        }
        Ok(None)
    }
}

/// Parse the X, Y, Z columns of one data row.
fn parse_row(line: &str, layout: &Layout) -> std::result::Result<Point3, String> {
    let need = layout.cols.iter().max().copied().unwrap_or(2) + 1;
    let mut p = [0.0; 3];
    let mut seen = 0;
    for (i, field) in layout.sep.split(line).enumerate().take(need) {
        seen = i + 1;
        for (v, &col) in p.iter_mut().zip(&layout.cols) {
            if col == i {
                *v = field
                    .parse::<f64>()
                    .map_err(|_| format!("'{field}' is not a number"))?;
            }
        }
    }
    if seen < need {
        return Err(if layout.cols == [0, 1, 2] {
            "expected 3 numbers".to_string()
        } else {
            format!(
                "expected at least {need} columns (X, Y, Z are columns {:?})",
                layout.cols.map(|c| c + 1)
            )
        });
    }
    Ok(p)
}

/// Find the layout: skip blank/comment lines and a PTS count line, recognise a header naming
/// X, Y, Z, otherwise take the first three columns of the first data line.
fn detect_layout(path: &Path) -> Result<Layout> {
    let mut f = open_file(path)?;
    // A binary file (PNG, a zip, ...) is refused up front rather than parsed line by line.
    let mut head = Vec::with_capacity(8192);
    (&mut f)
        .take(8192)
        .read_to_end(&mut head)
        .map_err(|e| Error::input(path, format!("cannot read: {e}")))?;
    if head.contains(&0) || (head.len() < 8192 && std::str::from_utf8(&head).is_err()) {
        return Err(Error::input(
            path,
            "not a point cloud: binary file that is not LAS, LAZ or PLY",
        ));
    }
    let mut lines = BufReader::new(open_file(path)?);
    let mut line = String::new();
    let mut line_no = 0u64;
    let mut header: Option<(Sep, [usize; 3])> = None;
    loop {
        line.clear();
        let n = lines.read_line(&mut line).map_err(|e| {
            Error::input(
                path,
                format!(
                    "line {}: cannot read as text ({e}); not a point cloud",
                    line_no + 1
                ),
            )
        })?;
        if n == 0 {
            return Err(Error::input(path, "contains no points"));
        }
        line_no += 1;
        if line_no == 1 {
            super::strip_bom(&mut line);
        }
        let (commented, body) = strip_comment(&line);
        if body.trim().is_empty() {
            continue;
        }
        let sep = Sep::detect(body);
        let fields: Vec<&str> = sep.split(body).collect();
        let numeric = fields.iter().all(|f| f.parse::<f64>().is_ok());
        if numeric && !commented {
            if header.is_none() && fields.len() == 1 && fields[0].parse::<u64>().is_ok() {
                continue; // PTS point-count line
            }
            if let Some((sep, cols)) = header {
                return Ok(Layout {
                    sep,
                    cols,
                    first_data_line: line_no,
                });
            }
            if fields.len() < 3 {
                return Err(Error::input(
                    path,
                    format!("line {line_no}: expected 3 numbers"),
                ));
            }
            return Ok(Layout {
                sep,
                cols: [0, 1, 2],
                first_data_line: line_no,
            });
        }
        if header.is_some() {
            if commented {
                continue;
            }
            return Err(Error::input(
                path,
                format!("line {line_no}: expected 3 numbers"),
            ));
        }
        let find = |name: &str| fields.iter().position(|f| f.eq_ignore_ascii_case(name));
        match (find("x"), find("y"), find("z")) {
            (Some(x), Some(y), Some(z)) => header = Some((sep, [x, y, z])),
            _ if commented => continue,
            _ => {
                return Err(Error::input(
                    path,
                    format!(
                        "not a point cloud: line {line_no} is neither a header naming X, Y, Z \
                         nor a row of numbers"
                    ),
                ))
            }
        }
    }
}

/// A streaming text reader; see the module doc.
pub(crate) struct TextReader {
    info: CloudInfo,
    pass: Pass,
}

impl TextReader {
    /// Open `path`, find its layout and scan it once for count and bounds.
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let layout = detect_layout(path)?;
        let mut scan = Pass::start(path, layout)?;
        let mut bounds = Bounds::empty();
        let mut count = 0u64;
        while let Some(p) = scan.next_point()? {
            bounds.grow(&p);
            count += 1;
        }
        if count == 0 {
            return Err(Error::input(path, "contains no points"));
        }
        let sep = match layout.sep {
            Sep::Comma => "comma-separated",
            Sep::Semicolon => "semicolon-separated",
            Sep::Whitespace => "whitespace-separated",
        };
        let info = CloudInfo {
            path: path.to_path_buf(),
            format: CloudFormat::Text,
            format_detail: format!(
                "text, {sep}, X/Y/Z in columns {}, {}, {}",
                layout.cols[0] + 1,
                layout.cols[1] + 1,
                layout.cols[2] + 1
            ),
            point_count: count,
            bounds,
            crs: Crs::default(),
            scale: None,
            transform: None,
        };
        Ok(TextReader {
            info,
            pass: Pass::start(path, layout)?,
        })
    }
}

impl PointReader for TextReader {
    fn info(&self) -> &CloudInfo {
        &self.info
    }

    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> Result<usize> {
        super::fill_from(buf, max, || self.pass.next_point())
    }
}
