//! Waypoint **programs**: named points the operator teaches on the panel, edits, saves,
//! loads and plays, and that `gui_bridge play FILE.csv` runs. Pure: no ROS, and no I/O
//! but the two small file helpers [`load`] and [`save`].
//!
//! # File format
//!
//! CSV, one point a row, `#` comments and blank lines allowed:
//!
//! ```text
//! x,y,z,gripper,dwell,mode,name
//! 0.20000,0.00000,0.15000,1.000,0.500,,above the box
//! 0.20000,0.00000,0.09000,0.000,1.000,line,pick
//! ```
//!
//! `x,y,z` is `tool0`'s position (m, `base_link`); `gripper` the claw opening 0 … 1 set
//! once there (empty: leave the claw as it is); `dwell` the seconds to stay (0 … 3600);
//! `mode` how to get there: `line` (the tool on a straight line: the target goes on
//! `xyz_line_target`), `joint` (on `xyz_target`, moved as compute_ik's `motion` says:
//! `joint`, every servo together, unless it was started with `motion:=line`) or empty
//! (as `joint`, or as `line` with the command line's `--line`; [`ProgramPoint::line`]
//! decides); `name` free text, the rest of the row (commas and
//! control characters become spaces, at most [`MAX_NAME_CHARS`] characters; empty: shown
//! as `P1`, `P2` … by [`ProgramPoint::label`]; a name that a spreadsheet would take for a
//! formula is written with a `'` in front, see [`name_cell`]). The older `x,y,z,gripper,dwell` files
//! and rows (what `record` writes) are read as well, with neither mode nor name.
//! Positions are kept to 10 µm, the claw and the dwell to 0.001: what [`Program::to_csv`]
//! prints, so a program read back from its file is equal to the one saved.
//!
//! # Examples
//!
//! ```
//! use gui_bridge::program::{MoveMode, Program, ProgramPoint};
//!
//! let mut p = Program::parse("x,y,z,gripper,dwell\n0.2,0,0.15,1,0.5\n")?;
//! p.teach(ProgramPoint::at([0.18, 0.05, 0.12]))?;
//! p.set_mode(1, Some(MoveMode::Line))?;
//! p.rename(1, "pick")?;
//! assert_eq!(p.points[0].label(0), "P1");
//! assert_eq!(Program::parse(&p.to_csv())?, p);
//! # Ok::<(), String>(())
//! ```

use serde::{Deserialize, Serialize};
use std::fmt;
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The header [`Program::to_csv`] writes.
pub const PROGRAM_HEADER: &str = "x,y,z,gripper,dwell,mode,name";
/// The most points a program holds.
pub const MAX_POINTS: usize = 1000;
/// The longest dwell (s).
pub const MAX_DWELL_S: f64 = 3600.0;
/// The longest point name, in characters.
pub const MAX_NAME_CHARS: usize = 64;
/// The longest program name (file name without `.csv`), in characters.
pub const MAX_PROGRAM_NAME_CHARS: usize = 64;
/// The largest program file [`load`] reads (bytes).
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// How a point is moved to: the topic its target goes on ([`ProgramPoint::line`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MoveMode {
    /// On `xyz_target`: as compute_ik's `motion` says (set at its start; `joint` by
    /// default: every servo within its limits, together).
    Joint,
    /// On `xyz_line_target`: the tool on a straight Cartesian line, refused before the
    /// move if any point of it is unreachable.
    Line,
}

impl MoveMode {
    /// As written in a program file: `joint` or `line`.
    pub fn as_str(self) -> &'static str {
        match self {
            MoveMode::Joint => "joint",
            MoveMode::Line => "line",
        }
    }
}

impl fmt::Display for MoveMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for MoveMode {
    type Err = String;

    /// `joint` or `line` (any case, blanks around ignored).
    fn from_str(s: &str) -> Result<MoveMode, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "joint" => Ok(MoveMode::Joint),
            "line" => Ok(MoveMode::Line),
            _ => Err(format!("mode `{}` is not joint or line", s.trim())),
        }
    }
}

/// One point of a program: where, how open, how long to stay, how to get there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgramPoint {
    /// The operator's name for it; empty: [`ProgramPoint::label`] shows `P1`, `P2` …
    #[serde(default)]
    pub name: String,
    /// `tool0` position (m, `base_link`).
    pub xyz: [f64; 3],
    /// Claw opening 0 (closed) … 1 (open) to set once there; `None` leaves it.
    #[serde(default)]
    pub gripper: Option<f64>,
    /// Seconds to stay once there (and the claw set), 0 … [`MAX_DWELL_S`].
    #[serde(default)]
    pub dwell_s: f64,
    /// How to get there; `None`: as `joint`, or as the command line's `--line` says
    /// ([`ProgramPoint::line`]).
    #[serde(default)]
    pub mode: Option<MoveMode>,
}

impl ProgramPoint {
    /// A point at `xyz` with no name, claw, dwell or mode.
    pub fn at(xyz: [f64; 3]) -> ProgramPoint {
        ProgramPoint {
            name: String::new(),
            xyz,
            gripper: None,
            dwell_s: 0.0,
            mode: None,
        }
    }

    /// Whether it is moved to on a straight line, its target on `xyz_line_target`: its
    /// own mode, else `default` (the command line's `--line`). Otherwise its target goes
    /// on `xyz_target`, moved as compute_ik's `motion` says. The one place where a move's
    /// kind is decided: the kind travels with each target, no parameter is switched.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::program::{MoveMode, ProgramPoint};
    /// let mut p = ProgramPoint::at([0.2, 0.0, 0.15]);
    /// assert!(!p.line(None) && p.line(Some(MoveMode::Line)));
    /// p.mode = Some(MoveMode::Joint);
    /// assert!(!p.line(Some(MoveMode::Line)), "its own mode first");
    /// ```
    pub fn line(&self, default: Option<MoveMode>) -> bool {
        self.mode.or(default) == Some(MoveMode::Line)
    }

    /// Its name, or `P{index + 1}` if it has none (`index` is its place in the program).
    pub fn label(&self, index: usize) -> String {
        if self.name.is_empty() {
            format!("P{}", index + 1)
        } else {
            self.name.clone()
        }
    }

    /// The point checked (finite position, claw and dwell within their ranges), with its
    /// values at the file's precision and its name sanitised.
    fn checked(&self) -> Result<ProgramPoint, String> {
        if let Some(bad) = self.xyz.iter().find(|v| !v.is_finite()) {
            return Err(format!("position {bad} is not a finite number"));
        }
        Ok(ProgramPoint {
            name: sanitize_name(&self.name),
            xyz: self.xyz.map(quantize_m),
            gripper: self.gripper.map(checked_gripper).transpose()?,
            dwell_s: checked_dwell(self.dwell_s)?,
            mode: self.mode,
        })
    }

    /// Its CSV row (the columns of [`PROGRAM_HEADER`]).
    pub fn to_row(&self) -> String {
        format!(
            "{:.5},{:.5},{:.5},{},{:.3},{},{}",
            self.xyz[0],
            self.xyz[1],
            self.xyz[2],
            self.gripper.map(|g| format!("{g:.3}")).unwrap_or_default(),
            self.dwell_s,
            self.mode.map(MoveMode::as_str).unwrap_or_default(),
            name_cell(&sanitize_name(&self.name))
        )
    }
}

/// A name as its CSV cell: a name a spreadsheet would take for a formula (starting with
/// `=`, `+`, `-`, `@`, a tab or a carriage return: OWASP's advice on CSV injection) gets
/// a `'` in front, which spreadsheets show as text; so does a name starting with `'`
/// itself, so that [`name_from_cell`] takes exactly one off.
///
/// # Examples
/// ```
/// use gui_bridge::program::{name_cell, name_from_cell};
/// assert_eq!(name_cell("=HYPERLINK(\"http://evil.example\")"), "'=HYPERLINK(\"http://evil.example\")");
/// assert_eq!(name_cell("pick"), "pick");
/// for name in ["=1+1", "+x", "-y", "@z", "'quoted", "pick"] {
///     assert_eq!(name_from_cell(&name_cell(name)), name);
/// }
/// ```
pub fn name_cell(name: &str) -> String {
    if name.starts_with(['=', '+', '-', '@', '\t', '\r', '\'']) {
        format!("'{name}")
    } else {
        name.to_string()
    }
}

/// A name from its CSV cell: one leading `'` (see [`name_cell`]) taken off.
pub fn name_from_cell(cell: &str) -> &str {
    cell.strip_prefix('\'').unwrap_or(cell)
}

/// A point name as it can be stored: commas and control characters (newlines, tabs …)
/// become spaces, blanks around are trimmed, at most [`MAX_NAME_CHARS`] characters.
///
/// # Examples
/// ```
/// assert_eq!(gui_bridge::program::sanitize_name(" pick, then\nlift "), "pick  then lift");
/// ```
pub fn sanitize_name(name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| if c == ',' || c.is_control() { ' ' } else { c })
        .collect();
    let cut: String = clean.trim().chars().take(MAX_NAME_CHARS).collect();
    cut.trim_end().to_string()
}

/// `v` as printed with `digits` decimals and read back (what a save and a load make of it).
fn quantize(v: f64, digits: usize) -> f64 {
    format!("{v:.digits$}").parse().unwrap_or(v)
}

fn quantize_m(v: f64) -> f64 {
    quantize(v, 5)
}

fn checked_gripper(g: f64) -> Result<f64, String> {
    if !(g.is_finite() && (0.0..=1.0).contains(&g)) {
        return Err(format!("gripper {g} is outside 0 (closed) … 1 (open)"));
    }
    Ok(quantize(g, 3))
}

fn checked_dwell(s: f64) -> Result<f64, String> {
    if !(s.is_finite() && (0.0..=MAX_DWELL_S).contains(&s)) {
        return Err(format!("dwell {s} s is outside 0 … {MAX_DWELL_S} s"));
    }
    Ok(quantize(s, 3))
}

/// A sequence of points to play in turn.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Program {
    /// The points, in playing order.
    pub points: Vec<ProgramPoint>,
}

impl Program {
    /// Parse a program file (see the [module](self) documentation): rows of
    /// `x,y,z,gripper,dwell[,mode[,name]]`, a header line (old or new) and `#` comments
    /// allowed. Errors name the line.
    ///
    /// # Examples
    /// ```
    /// use gui_bridge::program::{MoveMode, Program};
    ///
    /// let p = Program::parse("0.2,0,0.15,,0\n0.18,0.05,0.12,0.5,1,line,place\n")?;
    /// assert_eq!(p.points[1].mode, Some(MoveMode::Line));
    /// assert_eq!(p.points[1].name, "place");
    /// let e = Program::parse("0.2,0,0.15,,0\n0.2,zero,0.15,,0\n").unwrap_err();
    /// assert!(e.starts_with("line 2:"), "{e}");
    /// # Ok::<(), String>(())
    /// ```
    pub fn parse(text: &str) -> Result<Program, String> {
        const HEADERS: [&str; 3] = [
            "x,y,z,gripper,dwell",
            "x,y,z,gripper,dwell,mode",
            PROGRAM_HEADER,
        ];
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut points = vec![];
        for (i, line) in text.lines().enumerate() {
            let at = |e: String| format!("line {}: {e}", i + 1);
            let line = line.trim();
            let bare = line.replace([' ', '\t'], "").to_ascii_lowercase();
            if line.is_empty() || line.starts_with('#') || HEADERS.contains(&bare.as_str()) {
                continue;
            }
            if points.len() == MAX_POINTS {
                return Err(at(format!("more than {MAX_POINTS} points")));
            }
            // the name is the rest of the row: a comma in it is not a new column
            let fields: Vec<&str> = line.splitn(7, ',').map(str::trim).collect();
            if fields.len() < 5 {
                return Err(at(format!(
                    "expected 5 fields x,y,z,gripper,dwell (and optionally mode,name), got {}",
                    fields.len()
                )));
            }
            let num = |k: usize, what: &str| {
                fields[k]
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| at(format!("{what} `{}` is not a number", fields[k])))
            };
            let xyz = [num(0, "x")?, num(1, "y")?, num(2, "z")?];
            let gripper = if fields[3].is_empty() {
                None
            } else {
                Some(num(3, "gripper")?)
            };
            let mode = match fields.get(5) {
                None | Some(&"") => None,
                Some(m) => Some(m.parse::<MoveMode>().map_err(at)?),
            };
            let point = ProgramPoint {
                name: name_from_cell(fields.get(6).copied().unwrap_or_default()).to_string(),
                xyz,
                gripper,
                dwell_s: num(4, "dwell")?,
                mode,
            };
            points.push(point.checked().map_err(at)?);
        }
        Ok(Program { points })
    }

    /// The program as a file: [`PROGRAM_HEADER`], then a row a point (positions with 5
    /// decimals, claw and dwell with 3, names sanitised). Comments are not kept.
    pub fn to_csv(&self) -> String {
        let mut out = String::with_capacity(40 * (self.points.len() + 1));
        out.push_str(PROGRAM_HEADER);
        out.push('\n');
        for p in &self.points {
            out.push_str(&p.to_row());
            out.push('\n');
        }
        out
    }

    /// Check a program that did not come from [`Program::parse`] or the editing
    /// operations (one the panel sent whole): at most [`MAX_POINTS`], each point's
    /// position finite, claw and dwell within their ranges. Errors name the point (P1 …).
    pub fn validate(&self) -> Result<(), String> {
        if self.points.len() > MAX_POINTS {
            return Err(format!(
                "{} points: a program holds at most {MAX_POINTS}",
                self.points.len()
            ));
        }
        for (i, p) in self.points.iter().enumerate() {
            p.checked().map_err(|e| format!("P{}: {e}", i + 1))?;
        }
        Ok(())
    }

    /// Append a point (taught where the arm is). Its values are checked and kept at the
    /// file's precision, its name sanitised.
    pub fn teach(&mut self, point: ProgramPoint) -> Result<(), String> {
        if self.points.len() >= MAX_POINTS {
            return Err(format!("the program is full ({MAX_POINTS} points)"));
        }
        self.points.push(point.checked()?);
        Ok(())
    }

    /// Rename point `index` (sanitised as [`sanitize_name`]; empty: back to `P{index+1}`).
    pub fn rename(&mut self, index: usize, name: &str) -> Result<(), String> {
        self.point_mut(index)?.name = sanitize_name(name);
        Ok(())
    }

    /// Move point `from` so that it is at `to` afterwards (the others keep their order).
    pub fn move_to(&mut self, from: usize, to: usize) -> Result<(), String> {
        self.check_index(from)?;
        self.check_index(to)?;
        let p = self.points.remove(from);
        self.points.insert(to, p);
        Ok(())
    }

    /// Delete point `index`.
    pub fn remove(&mut self, index: usize) -> Result<(), String> {
        self.check_index(index)?;
        self.points.remove(index);
        Ok(())
    }

    /// Set point `index`'s dwell (s, 0 … [`MAX_DWELL_S`]).
    pub fn set_dwell(&mut self, index: usize, dwell_s: f64) -> Result<(), String> {
        let dwell_s = checked_dwell(dwell_s)?;
        self.point_mut(index)?.dwell_s = dwell_s;
        Ok(())
    }

    /// Set how point `index` is moved to (`None`: as compute_ik is set).
    pub fn set_mode(&mut self, index: usize, mode: Option<MoveMode>) -> Result<(), String> {
        self.point_mut(index)?.mode = mode;
        Ok(())
    }

    /// Set point `index`'s claw opening (0 … 1; `None`: leave the claw as it is).
    pub fn set_gripper(&mut self, index: usize, gripper: Option<f64>) -> Result<(), String> {
        let gripper = gripper.map(checked_gripper).transpose()?;
        self.point_mut(index)?.gripper = gripper;
        Ok(())
    }

    fn check_index(&self, index: usize) -> Result<(), String> {
        match self.points.len() {
            0 => Err(format!("no point {index}: the program is empty")),
            n if index >= n => Err(format!(
                "no point {index}: the program has points 0 … {}",
                n - 1
            )),
            _ => Ok(()),
        }
    }

    fn point_mut(&mut self, index: usize) -> Result<&mut ProgramPoint, String> {
        self.check_index(index)?;
        self.points
            .get_mut(index)
            .ok_or_else(|| format!("no point {index}"))
    }
}

/// The file of program `name` in `dir`: `dir/name.csv`. Only names of 1 to
/// [`MAX_PROGRAM_NAME_CHARS`] characters `A-Z a-z 0-9 _ -` are accepted (no paths, no
/// dots); a `.csv` suffix on `name` is allowed and stands for the same file.
///
/// # Examples
/// ```
/// use gui_bridge::program::program_path;
/// use std::path::Path;
///
/// let dir = Path::new("/srv/programs");
/// assert_eq!(program_path(dir, "pick_and-place")?, dir.join("pick_and-place.csv"));
/// assert_eq!(program_path(dir, "pick.csv")?, dir.join("pick.csv"));
/// assert!(program_path(dir, "../etc/passwd").is_err());
/// # Ok::<(), String>(())
/// ```
pub fn program_path(dir: &Path, name: &str) -> Result<PathBuf, String> {
    let stem = name.strip_suffix(".csv").unwrap_or(name);
    let valid = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    if stem.is_empty() || stem.len() > MAX_PROGRAM_NAME_CHARS || !stem.chars().all(valid) {
        return Err(format!(
            "program name {:?}: use 1 to {MAX_PROGRAM_NAME_CHARS} of A-Z a-z 0-9 _ -",
            shorten(name)
        ));
    }
    Ok(dir.join(format!("{stem}.csv")))
}

/// `name` cut for an error message.
fn shorten(name: &str) -> String {
    ros_plumbing::logging::printable(name, 80)
}

/// The programs in `dir`: the names (without `.csv`) of its regular `*.csv` files (not
/// symbolic links, FIFOs or devices) that [`program_path`] accepts, sorted; none if
/// `dir` cannot be read.
pub fn list_programs(dir: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return vec![];
    };
    let mut names: Vec<String> = entries
        .filter_map(Result::ok)
        // the entry's own type: a symbolic link is not followed
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| {
            let file = e.file_name().into_string().ok()?;
            let stem = file.strip_suffix(".csv")?;
            program_path(dir, stem).ok().map(|_| stem.to_string())
        })
        .collect();
    names.sort();
    names
}

/// Why a program file could not be read or written. The texts name the program, never
/// a path, and never show the file's content.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ProgramFileError {
    /// Not a usable program name (see [`program_path`]).
    #[error("{0}")]
    BadName(String),
    /// Saving would replace a program that exists (save again with `overwrite`).
    #[error("a program named {name} exists already: saving again replaces it")]
    Exists {
        /// the program
        name: String,
    },
    /// The file is not a regular file: a symbolic link, a FIFO, a device, a directory.
    #[error(
        "program {name} is not a regular file (symbolic links, FIFOs and devices are refused)"
    )]
    NotRegular {
        /// the program
        name: String,
    },
    /// The file is over [`MAX_FILE_BYTES`].
    #[error("program {name} is larger than {MAX_FILE_BYTES} bytes")]
    TooLarge {
        /// the program
        name: String,
    },
    /// The content is not a program.
    #[error("program {name}: {why}")]
    Invalid {
        /// the program
        name: String,
        /// what is wrong (the line)
        why: String,
    },
    /// Reading or writing failed (the OS's reason, e.g. "No such file or directory").
    #[error("cannot {what} program {name}: {why}")]
    Io {
        /// `read` or `write`
        what: &'static str,
        /// the program
        name: String,
        /// the OS's reason, without the path
        why: String,
    },
    /// The file system did not answer in time (a hung network mount).
    #[error("program {name}: the file system did not answer within {seconds} s")]
    TimedOut {
        /// the program
        name: String,
        /// the timeout
        seconds: u64,
    },
}

/// The OS's reason without the path (`std::io::Error`'s text has none; kept so).
fn io_why(e: &std::io::Error) -> String {
    match e.raw_os_error() {
        // O_NOFOLLOW on a symbolic link
        Some(40) => "it is a symbolic link".into(),
        _ => e.kind().to_string(),
    }
}

/// Open `path` for reading only if it is a regular file: `O_NOFOLLOW` (a symbolic link
/// fails), `O_NONBLOCK` (opening a FIFO does not wait for a writer), then `fstat` of
/// what was opened must say regular file (no FIFO, device, directory).
pub fn open_regular(path: &Path, name: &str) -> Result<std::fs::File, ProgramFileError> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use nix::fcntl::OFlag;
        use std::os::unix::fs::OpenOptionsExt as _;
        options.custom_flags((OFlag::O_NOFOLLOW | OFlag::O_NONBLOCK).bits());
    }
    let not_regular = || ProgramFileError::NotRegular {
        name: name.to_string(),
    };
    let file = options.open(path).map_err(|e| match e.raw_os_error() {
        Some(40) => not_regular(), // ELOOP: a symbolic link
        _ => ProgramFileError::Io {
            what: "read",
            name: name.to_string(),
            why: io_why(&e),
        },
    })?;
    let meta = file.metadata().map_err(|e| ProgramFileError::Io {
        what: "read",
        name: name.to_string(),
        why: io_why(&e),
    })?;
    if !meta.file_type().is_file() {
        return Err(not_regular());
    }
    Ok(file)
}

/// The stem of program `name` (no `.csv`), for messages.
fn stem(name: &str) -> &str {
    name.strip_suffix(".csv").unwrap_or(name)
}

/// Read program `name` from `dir`: a regular file only ([`open_regular`]), at most
/// [`MAX_FILE_BYTES`]. Blocking: the panel calls it off its event loop, with a timeout.
pub fn load(dir: &Path, name: &str) -> Result<Program, ProgramFileError> {
    let path = program_path(dir, name).map_err(ProgramFileError::BadName)?;
    let name = stem(name);
    let file = open_regular(&path, name)?;
    let mut text = String::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| ProgramFileError::Io {
            what: "read",
            name: name.to_string(),
            why: io_why(&e),
        })?;
    if text.len() as u64 > MAX_FILE_BYTES {
        return Err(ProgramFileError::TooLarge {
            name: name.to_string(),
        });
    }
    Program::parse(&text).map_err(|why| ProgramFileError::Invalid {
        name: name.to_string(),
        why,
    })
}

/// Write `program` as program `name` in `dir` (created if missing): written to a new
/// temporary file in `dir`, then put in place. Without `overwrite` an existing program is
/// left as it is ([`ProgramFileError::Exists`]: the new file is linked in only if the name
/// is free, atomically); with it, renamed over it (a symbolic link of that name is
/// replaced, not followed). Blocking: the panel calls it off its event loop.
pub fn save(
    dir: &Path,
    name: &str,
    program: &Program,
    overwrite: bool,
) -> Result<(), ProgramFileError> {
    static SAVES: AtomicU64 = AtomicU64::new(0);
    let path = program_path(dir, name).map_err(ProgramFileError::BadName)?;
    let name = stem(name);
    let invalid = |why| ProgramFileError::Invalid {
        name: name.to_string(),
        why,
    };
    program.validate().map_err(invalid)?;
    let text = program.to_csv();
    if text.len() as u64 > MAX_FILE_BYTES {
        return Err(ProgramFileError::TooLarge {
            name: name.to_string(),
        });
    }
    let io = |e: std::io::Error| ProgramFileError::Io {
        what: "write",
        name: name.to_string(),
        why: io_why(&e),
    };
    std::fs::create_dir_all(dir).map_err(io)?;
    // a dot file without `.csv`: never listed, never taken for a program
    let tmp = dir.join(format!(
        ".{name}.csv.tmp{}-{}",
        std::process::id(),
        SAVES.fetch_add(1, Ordering::Relaxed)
    ));
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| {
            f.write_all(text.as_bytes())?;
            f.sync_all()
        });
    let placed = written.and_then(|()| {
        if overwrite {
            std::fs::rename(&tmp, &path)
        } else {
            std::fs::hard_link(&tmp, &path)
        }
    });
    let _ = std::fs::remove_file(&tmp);
    placed.map_err(|e| match e.kind() {
        std::io::ErrorKind::AlreadyExists => ProgramFileError::Exists {
            name: name.to_string(),
        },
        _ => io(e),
    })
}

/// How close (m) the observed `tool0` must come to a point for the [`Player`] to count it
/// reached: 2 mm, several servo steps (about 0.3 mm of tool travel each) yet well under
/// anything an operator would teach apart. compute_ik's motions end exactly on the
/// target, so the last few steps of a motion are where this is met.
pub const ARRIVAL_TOLERANCE_M: f64 = 0.002;
/// How long the [`Player`] waits for the arm to reach a point before failing.
pub const MOVE_TIMEOUT: Duration = Duration::from_secs(30);

/// What the node must do for the [`Player`], from [`Player::step`], in order.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlayerAction {
    /// Send point `index`'s position as the target.
    Target {
        /// the point's place in the program
        index: usize,
        /// where (m, `base_link`)
        xyz: [f64; 3],
        /// on a straight line (`xyz_line_target`), else on `xyz_target`
        /// ([`ProgramPoint::line`])
        line: bool,
    },
    /// Set the claw opening (0 … 1), at the point just reached.
    Gripper(f64),
    /// Point `index` was reached (its dwell starts).
    Arrived {
        /// the point's place in the program
        index: usize,
    },
    /// The last point's dwell is over (never when looping).
    Finished,
    /// The playback stopped at point `index`.
    Failed {
        /// the point's place in the program
        index: usize,
        /// why (a refusal's reason, a timeout)
        reason: String,
    },
}

/// What the [`Player`] is doing, for the panel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlayerPhase {
    /// On the way to the point (or about to send it).
    Moving,
    /// At the point, staying its dwell.
    Dwelling,
    /// Every point played.
    Finished,
    /// Stopped by a failure.
    Failed,
    /// Stopped by the operator.
    Stopped,
}

/// The [`Player`]'s state for the panel:
/// `{"index": 2, "phase": "dwelling", "loop": 0}` (and `"reason"` once failed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlayerState {
    /// The point being played (the last one once finished).
    pub index: usize,
    /// What the player is doing.
    pub phase: PlayerPhase,
    /// How many times the whole program has been played (looping).
    #[serde(rename = "loop")]
    pub loops: usize,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// Where a [`Player`] is within a point.
#[derive(Debug, Clone, PartialEq)]
enum Phase {
    /// Send the current point's target at the next step.
    Begin,
    /// Target sent at the step before; waiting for the tool to arrive until `deadline`.
    Moving {
        deadline: Instant,
    },
    /// Arrived; staying until `until`.
    Dwelling {
        until: Instant,
    },
    Finished,
    Failed {
        reason: String,
    },
    Stopped,
}

/// Plays a [`Program`]: a state machine driven by time and observations, without I/O.
///
/// The node calls [`Player::step`] with the time and, when it has a new one, `tool0`'s
/// observed position, carries out the [`PlayerAction`]s it returns, reports a refusal
/// with [`Player::refused`] (then calls `step` again), and calls `step` by
/// [`Player::next_wakeup`] at the latest. For each point: `Target` (with the move's kind,
/// [`ProgramPoint::line`]), wait until a tool position observed *after* the target was
/// sent is within [`ARRIVAL_TOLERANCE_M`] ([`MOVE_TIMEOUT`] at most), `Arrived`,
/// `Gripper` if it has one, then its dwell; after the last point `Finished`, or from
/// point 0 again when looping. Nothing is switched between moves of different kinds.
///
/// # Examples
/// ```
/// use gui_bridge::program::{Player, PlayerAction, Program, ProgramPoint};
/// use std::time::{Duration, Instant};
///
/// let mut program = Program::default();
/// program.teach(ProgramPoint::at([0.2, 0.0, 0.15]))?;
/// let t0 = Instant::now();
/// let mut player = Player::start(&program, false, t0)?;
/// assert_eq!(player.step(t0, None), [PlayerAction::Target { index: 0, xyz: [0.2, 0.0, 0.15], line: false }]);
/// let t1 = t0 + Duration::from_secs(1);
/// assert_eq!(player.step(t1, Some([0.2, 0.0005, 0.15])), [PlayerAction::Arrived { index: 0 }, PlayerAction::Finished]);
/// assert_eq!(player.next_wakeup(), None);
/// # Ok::<(), String>(())
/// ```
#[derive(Debug, Clone)]
pub struct Player {
    points: Vec<ProgramPoint>,
    looping: bool,
    index: usize,
    loops: usize,
    phase: Phase,
    /// for points without a mode, if set: see [`Player::with_base_mode`]
    base_mode: Option<MoveMode>,
    /// actions of [`Player::refused`] (a failure) for the next step
    pending: Vec<PlayerAction>,
    /// the time of the last step (or of the start)
    now: Instant,
}

impl Player {
    /// Start playing (a copy of) `program` from its first point; `looping`: over and over
    /// until stopped. Call [`Player::step`] now. An empty or invalid program is refused.
    pub fn start(program: &Program, looping: bool, now: Instant) -> Result<Player, String> {
        if program.points.is_empty() {
            return Err("the program has no points".into());
        }
        program.validate()?;
        Ok(Player {
            points: program.points.clone(),
            looping,
            index: 0,
            loops: 0,
            phase: Phase::Begin,
            base_mode: None,
            pending: vec![],
            now,
        })
    }

    /// Points without a mode are moved to as `mode` says (as `gui_bridge play --line`
    /// does: [`ProgramPoint::line`]); without it, as `joint`.
    pub fn with_base_mode(mut self, mode: MoveMode) -> Player {
        self.base_mode = Some(mode);
        self
    }

    /// Stop playing (the operator's stop): no more actions.
    pub fn stop(&mut self) {
        if self.is_running() {
            self.phase = Phase::Stopped;
            self.pending.clear();
        }
    }

    /// Whether it is still playing (not finished, failed or stopped).
    pub fn is_running(&self) -> bool {
        !matches!(
            self.phase,
            Phase::Finished | Phase::Failed { .. } | Phase::Stopped
        )
    }

    /// compute_ik refused the target sent last (its diagnostics carried that target's
    /// stamp under `last_rejection_stamp`: the node matches the stamps): fails the
    /// playback with `reason`. Ignored unless a target is on its way. Call
    /// [`Player::step`] next.
    pub fn refused(&mut self, reason: &str) {
        if matches!(self.phase, Phase::Moving { .. }) {
            self.fail(format!("refused: {reason}"));
        }
    }

    fn fail(&mut self, reason: String) {
        self.pending.push(PlayerAction::Failed {
            index: self.index,
            reason: reason.clone(),
        });
        self.phase = Phase::Failed { reason };
    }

    /// Advance to `now` with `tool`, `tool0`'s position if one was observed since the last
    /// step: the actions to carry out, in order.
    pub fn step(&mut self, now: Instant, tool: Option<[f64; 3]>) -> Vec<PlayerAction> {
        self.now = now;
        let mut out = std::mem::take(&mut self.pending);
        // each pass either changes phase or returns; a target sent ends the step (its
        // arrival is judged on later observations), so this ends
        loop {
            let Some(point) = self.points.get(self.index) else {
                // not reachable: `start` refuses empty programs and `index` stays within
                if self.is_running() {
                    self.fail(format!("no point {}", self.index));
                    out.append(&mut self.pending);
                }
                return out;
            };
            match self.phase {
                Phase::Begin => {
                    out.push(PlayerAction::Target {
                        index: self.index,
                        xyz: point.xyz,
                        line: point.line(self.base_mode),
                    });
                    self.phase = Phase::Moving {
                        deadline: now + MOVE_TIMEOUT,
                    };
                    return out;
                }
                Phase::Moving { deadline } => {
                    let arrived =
                        tool.is_some_and(|t| distance(t, point.xyz) <= ARRIVAL_TOLERANCE_M);
                    if arrived {
                        out.push(PlayerAction::Arrived { index: self.index });
                        if let Some(g) = point.gripper {
                            out.push(PlayerAction::Gripper(g));
                        }
                        self.phase = Phase::Dwelling {
                            // `start` checked it: 0 … 3600 s
                            until: now
                                + Duration::try_from_secs_f64(point.dwell_s).unwrap_or_default(),
                        };
                    } else {
                        if now >= deadline {
                            let s = MOVE_TIMEOUT.as_secs_f64();
                            self.fail(format!("did not arrive at {:?} in {s:.0} s", point.xyz));
                            out.append(&mut self.pending);
                        }
                        return out;
                    }
                }
                Phase::Dwelling { until } => {
                    if now < until {
                        return out;
                    }
                    if self.index + 1 < self.points.len() {
                        self.index += 1;
                    } else if self.looping {
                        self.index = 0;
                        self.loops += 1;
                    } else {
                        out.push(PlayerAction::Finished);
                        self.phase = Phase::Finished;
                        return out;
                    }
                    self.phase = Phase::Begin;
                }
                Phase::Finished | Phase::Failed { .. } | Phase::Stopped => return out,
            }
        }
    }

    /// When [`Player::step`] must be called again even without an observation (a
    /// timeout, the end of a dwell; a time already past: now); `None` once over.
    pub fn next_wakeup(&self) -> Option<Instant> {
        if !self.pending.is_empty() {
            return Some(self.now);
        }
        match self.phase {
            Phase::Begin => Some(self.now),
            Phase::Moving { deadline } => Some(deadline),
            Phase::Dwelling { until } => Some(until),
            Phase::Finished | Phase::Failed { .. } | Phase::Stopped => None,
        }
    }

    /// What it is doing, for the panel.
    pub fn state(&self) -> PlayerState {
        let (phase, reason) = match &self.phase {
            Phase::Begin | Phase::Moving { .. } => (PlayerPhase::Moving, None),
            Phase::Dwelling { .. } => (PlayerPhase::Dwelling, None),
            Phase::Finished => (PlayerPhase::Finished, None),
            Phase::Failed { reason } => (PlayerPhase::Failed, Some(reason.clone())),
            Phase::Stopped => (PlayerPhase::Stopped, None),
        };
        PlayerState {
            index: self.index,
            phase,
            loops: self.loops,
            reason,
        }
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(
        name: &str,
        xyz: [f64; 3],
        gripper: Option<f64>,
        dwell_s: f64,
        mode: Option<MoveMode>,
    ) -> ProgramPoint {
        ProgramPoint {
            name: name.into(),
            xyz,
            gripper,
            dwell_s,
            mode,
        }
    }

    /// A point at `xyz` with no name, claw, dwell or mode.
    fn to(xyz: [f64; 3]) -> ProgramPoint {
        point("", xyz, None, 0.0, None)
    }

    /// [`to`] `xyz` in line mode.
    fn line(xyz: [f64; 3]) -> ProgramPoint {
        point("", xyz, None, 0.0, Some(MoveMode::Line))
    }

    /// [`to`] `xyz` in joint mode.
    fn joint(xyz: [f64; 3]) -> ProgramPoint {
        point("", xyz, None, 0.0, Some(MoveMode::Joint))
    }

    fn three() -> Program {
        Program {
            points: vec![
                point("above", [0.2, 0.0, 0.15], Some(1.0), 0.5, None),
                point(
                    "pick",
                    [0.2, 0.0, 0.09],
                    Some(0.0),
                    1.0,
                    Some(MoveMode::Line),
                ),
                point("", [0.18, 0.05, 0.12], None, 0.0, Some(MoveMode::Joint)),
            ],
        }
    }

    #[test]
    fn csv_round_trip_is_exact_at_the_printed_precision() {
        let p = Program {
            points: vec![
                point(
                    "a b",
                    [0.12345, -0.06789, 0.2],
                    Some(0.125),
                    1.25,
                    Some(MoveMode::Line),
                ),
                point("", [0.0, 0.0, 0.1], None, 3600.0, None),
                point(
                    "Greifer zu ü",
                    [-0.1, 0.00001, 0.3],
                    Some(1.0),
                    0.001,
                    Some(MoveMode::Joint),
                ),
            ],
        };
        let text = p.to_csv();
        assert!(
            text.starts_with("x,y,z,gripper,dwell,mode,name\n"),
            "{text}"
        );
        assert!(
            text.contains("\n0.12345,-0.06789,0.20000,0.125,1.250,line,a b\n"),
            "{text}"
        );
        assert!(
            text.contains("\n0.00000,0.00000,0.10000,,3600.000,,\n"),
            "{text}"
        );
        assert_eq!(Program::parse(&text).unwrap(), p);
        assert_eq!(Program::parse(&text).unwrap().to_csv(), text);
        assert_eq!(
            Program::parse(&Program::default().to_csv()).unwrap(),
            Program::default()
        );
        // more decimals than printed: kept at the printed precision, then exact
        let q = Program::parse("0.1234567,0,0.15,0.33333,0.00049\n").unwrap();
        assert_eq!(q.points[0].xyz, [0.12346, 0.0, 0.15]);
        assert_eq!(
            (q.points[0].gripper, q.points[0].dwell_s),
            (Some(0.333), 0.0)
        );
        assert_eq!(Program::parse(&q.to_csv()).unwrap(), q);
    }

    #[test]
    fn old_five_column_files_and_rows_still_parse() {
        let old = "x,y,z,gripper,dwell\n0.2,0,0.15,0.5,0.2\n# a comment\n\n0.18,0.05,0.12,,0.1\n";
        let p = Program::parse(old).unwrap();
        assert_eq!(
            p.points,
            vec![
                point("", [0.2, 0.0, 0.15], Some(0.5), 0.2, None),
                point("", [0.18, 0.05, 0.12], None, 0.1, None),
            ]
        );
        assert_eq!(
            (p.points[0].label(0), p.points[1].label(1)),
            ("P1".into(), "P2".into())
        );
        // the old five columns with their header, mixed with new rows
        let text = "x,y,z,gripper,dwell\n0.20000,-0.04000,0.18000,1.000,0.250\n0.2,0,0.15,,0,line\n0.2,0,0.15,,0,,named\n";
        let w = point("", [0.2, -0.04, 0.18], Some(1.0), 0.25, None);
        let p = Program::parse(text).unwrap();
        assert_eq!(p.points[0], w);
        assert_eq!(p.points[1].mode, Some(MoveMode::Line));
        assert_eq!(
            (p.points[2].mode, p.points[2].name.as_str()),
            (None, "named")
        );
        // headers with blanks, the new header, a byte-order mark, spaces around fields
        let p = Program::parse(
            "\u{feff}x, y, z, gripper, dwell, mode, name\n 0.2 , 0 , 0.15 , , 1 , LINE , pick \n",
        )
        .unwrap();
        assert_eq!(
            p.points,
            vec![point(
                "pick",
                [0.2, 0.0, 0.15],
                None,
                1.0,
                Some(MoveMode::Line)
            )]
        );
    }

    #[test]
    fn names_with_commas_and_control_characters_are_sanitised() {
        let p = Program::parse("0.2,0,0.15,,0,,pick, then lift\n").unwrap();
        assert_eq!(p.points[0].name, "pick  then lift");
        let mut p = Program::default();
        p.teach(point("a,b\nc\td\u{7}", [0.2, 0.0, 0.15], None, 0.0, None))
            .unwrap();
        assert_eq!(p.points[0].name, "a b c d");
        let long = "x".repeat(100);
        p.rename(0, &long).unwrap();
        assert_eq!(p.points[0].name.chars().count(), MAX_NAME_CHARS);
        p.rename(0, &"é".repeat(70)).unwrap();
        assert_eq!(p.points[0].name, "é".repeat(64));
        // a program the panel sent whole: its rows stay rows
        let raw = Program {
            points: vec![point("evil,1,2\n3,4,5", [0.2, 0.0, 0.15], None, 0.0, None)],
        };
        let text = raw.to_csv();
        assert_eq!(text.lines().count(), 2, "{text}");
        assert_eq!(
            Program::parse(&text).unwrap().points[0].name,
            "evil 1 2 3 4 5"
        );
        assert_eq!(sanitize_name("  \n "), "");
    }

    #[test]
    fn bad_lines_are_refused_with_their_number() {
        for (text, line, words) in [
            (
                "0.2,0,0.15,,0\n0.2,zero,0.15,,0\n",
                2,
                "y `zero` is not a number",
            ),
            (
                "x,y,z,gripper,dwell\n\n0.2,0,0.15,0\n",
                3,
                "expected 5 fields",
            ),
            ("0.2,0,0.15,2,0\n", 1, "gripper 2 is outside"),
            ("0.2,0,0.15,-0.1,0\n", 1, "gripper -0.1 is outside"),
            ("0.2,0,0.15,,-1\n", 1, "dwell -1 s is outside"),
            ("0.2,0,0.15,,3600.5\n", 1, "dwell 3600.5 s is outside"),
            ("# c\n0.2,0,nan,,0\n", 2, "z `nan` is not a number"),
            ("0.2,inf,0.1,,0\n", 1, "y `inf` is not a number"),
            (
                "0.2,0,0.15,,0,fly,x\n",
                1,
                "mode `fly` is not joint or line",
            ),
            ("0.2,0,0.15,,\n", 1, "dwell `` is not a number"),
        ] {
            let e = Program::parse(text).unwrap_err();
            assert!(e.starts_with(&format!("line {line}: ")), "{text:?}: {e}");
            assert!(e.contains(words), "{text:?}: {e}");
        }
    }

    #[test]
    fn at_most_1000_points() {
        let row = "0.2,0,0.15,,0\n";
        assert_eq!(
            Program::parse(&row.repeat(MAX_POINTS))
                .unwrap()
                .points
                .len(),
            MAX_POINTS
        );
        let e = Program::parse(&format!("# c\n{}", row.repeat(MAX_POINTS + 1))).unwrap_err();
        assert!(e.starts_with("line 1002: more than 1000 points"), "{e}");
        let mut p = Program::parse(&row.repeat(MAX_POINTS)).unwrap();
        assert!(p
            .teach(ProgramPoint::at([0.2, 0.0, 0.15]))
            .unwrap_err()
            .contains("full"));
        p.points.push(ProgramPoint::at([0.2, 0.0, 0.15]));
        assert!(p.validate().unwrap_err().contains("at most 1000"));
    }

    #[test]
    fn teach_appends_checked_points() {
        let mut p = Program::default();
        p.teach(point("", [0.2000012, 0.0, 0.15], Some(0.5004), 0.25, None))
            .unwrap();
        assert_eq!(p.points[0].xyz, [0.2, 0.0, 0.15]);
        assert_eq!(p.points[0].gripper, Some(0.5));
        p.teach(ProgramPoint::at([0.1, 0.1, 0.1])).unwrap();
        assert_eq!(p.points.len(), 2);
        for bad in [
            point("", [f64::NAN, 0.0, 0.15], None, 0.0, None),
            point("", [0.2, f64::INFINITY, 0.15], None, 0.0, None),
            point("", [0.2, 0.0, 0.15], Some(1.01), 0.0, None),
            point("", [0.2, 0.0, 0.15], Some(f64::NAN), 0.0, None),
            point("", [0.2, 0.0, 0.15], None, -0.5, None),
            point("", [0.2, 0.0, 0.15], None, 4000.0, None),
        ] {
            assert!(p.teach(bad.clone()).is_err(), "{bad:?}");
        }
        assert_eq!(p.points.len(), 2, "a refused point changes nothing");
    }

    #[test]
    fn rename_move_remove_refuse_indexes_out_of_range() {
        let mut p = three();
        p.rename(2, "place").unwrap();
        assert_eq!(p.points[2].name, "place");
        p.rename(0, "").unwrap();
        assert_eq!(p.points[0].label(0), "P1");
        let e = p.rename(3, "x").unwrap_err();
        assert_eq!(e, "no point 3: the program has points 0 … 2");
        // move_to: the point ends at `to`
        let names = |p: &Program| p.points.iter().map(|q| q.name.clone()).collect::<Vec<_>>();
        p.move_to(0, 2).unwrap();
        assert_eq!(names(&p), ["pick", "place", ""]);
        p.move_to(2, 0).unwrap();
        assert_eq!(names(&p), ["", "pick", "place"]);
        p.move_to(1, 1).unwrap();
        assert_eq!(names(&p), ["", "pick", "place"]);
        assert!(p.move_to(3, 0).is_err());
        assert!(p.move_to(0, 3).is_err());
        assert_eq!(names(&p), ["", "pick", "place"]);
        p.remove(1).unwrap();
        assert_eq!(names(&p), ["", "place"]);
        assert!(p.remove(2).is_err());
        p.remove(0).unwrap();
        p.remove(0).unwrap();
        assert_eq!(p.remove(0).unwrap_err(), "no point 0: the program is empty");
        assert!(p.rename(0, "x").is_err() && p.move_to(0, 0).is_err());
    }

    #[test]
    fn set_dwell_mode_and_gripper_check_their_input() {
        let mut p = three();
        p.set_dwell(0, 2.5).unwrap();
        assert_eq!(p.points[0].dwell_s, 2.5);
        p.set_dwell(0, 0.0).unwrap();
        p.set_dwell(0, MAX_DWELL_S).unwrap();
        for bad in [-0.1, 3600.1, f64::NAN, f64::INFINITY] {
            assert!(p.set_dwell(0, bad).unwrap_err().contains("dwell"), "{bad}");
        }
        assert!(p.set_dwell(3, 1.0).is_err());
        assert_eq!(p.points[0].dwell_s, MAX_DWELL_S);
        p.set_mode(0, Some(MoveMode::Line)).unwrap();
        assert_eq!(p.points[0].mode, Some(MoveMode::Line));
        p.set_mode(1, None).unwrap();
        assert_eq!(p.points[1].mode, None);
        assert!(p.set_mode(3, None).is_err());
        p.set_gripper(2, Some(0.25)).unwrap();
        assert_eq!(p.points[2].gripper, Some(0.25));
        p.set_gripper(2, None).unwrap();
        assert_eq!(p.points[2].gripper, None);
        for bad in [-0.01, 1.5, f64::NAN] {
            assert!(
                p.set_gripper(2, Some(bad)).unwrap_err().contains("gripper"),
                "{bad}"
            );
        }
        assert!(p.set_gripper(3, Some(0.5)).is_err());
        assert_eq!(p.points[2].gripper, None);
    }

    #[test]
    fn validate_names_the_bad_point() {
        let mut p = three();
        assert_eq!(p.validate(), Ok(()));
        p.points[1].dwell_s = -1.0;
        assert!(p.validate().unwrap_err().starts_with("P2: dwell"));
    }

    #[test]
    fn json_for_the_panel() {
        let p = three();
        let v = serde_json::to_value(&p).unwrap();
        assert_eq!(v["points"][1]["mode"], "line");
        assert_eq!(v["points"][0]["mode"], serde_json::Value::Null);
        assert_eq!(v["points"][2]["mode"], "joint");
        assert_eq!(v["points"][0]["dwell_s"], 0.5);
        assert_eq!(serde_json::from_value::<Program>(v).unwrap(), p);
        let q: ProgramPoint =
            serde_json::from_str(r#"{"xyz": [0.2, 0, 0.15], "mode": "joint"}"#).unwrap();
        assert_eq!(
            q,
            point("", [0.2, 0.0, 0.15], None, 0.0, Some(MoveMode::Joint))
        );
        assert!(
            serde_json::from_str::<ProgramPoint>(r#"{"xyz": [0.2, 0, 0.15], "mode": "fly"}"#)
                .is_err()
        );
        assert!(
            serde_json::from_str::<ProgramPoint>(r#"{"xyz": [0.2, 0, 0.15], "speed": 1}"#).is_err()
        );
        let s = PlayerState {
            index: 2,
            phase: PlayerPhase::Dwelling,
            loops: 1,
            reason: None,
        };
        assert_eq!(
            serde_json::to_value(&s).unwrap(),
            serde_json::json!({"index": 2, "phase": "dwelling", "loop": 1})
        );
    }

    #[test]
    fn program_path_takes_plain_names_only() {
        let dir = Path::new("/srv/programs");
        assert_eq!(program_path(dir, "pick").unwrap(), dir.join("pick.csv"));
        assert_eq!(program_path(dir, "pick.csv").unwrap(), dir.join("pick.csv"));
        assert_eq!(program_path(dir, "A-z_09").unwrap(), dir.join("A-z_09.csv"));
        let max = "a".repeat(64);
        assert_eq!(
            program_path(dir, &max).unwrap(),
            dir.join(format!("{max}.csv"))
        );
        assert!(program_path(dir, &format!("{max}.csv")).is_ok());
        for bad in [
            "",
            ".csv",
            "../x",
            "..",
            "a/b",
            "a\\b",
            "/etc/passwd",
            "a.b",
            "a.csv.csv",
            "pick.CSV",
            " pick",
            "pi ck",
            "pïck",
            "a\0",
            &"a".repeat(65),
        ] {
            let e = program_path(dir, bad).unwrap_err();
            assert!(e.contains("A-Z a-z 0-9 _ -"), "{bad:?}: {e}");
        }
    }

    /// A fresh directory under the system's temporary one, removed when dropped.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> TempDir {
            let dir = std::env::temp_dir()
                .join(format!("gui_bridge_program_{tag}_{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn save_load_and_list() {
        let tmp = TempDir::new("files");
        let dir = tmp.0.join("programs");
        assert!(list_programs(&dir).is_empty(), "missing dir: none");
        let p = three();
        save(&dir, "pick_place", &p, false).unwrap();
        save(&dir, "a-first.csv", &Program::default(), false).unwrap();
        assert_eq!(load(&dir, "pick_place").unwrap(), p);
        assert_eq!(load(&dir, "pick_place.csv").unwrap(), p);
        // replaced whole, and only when asked to
        let mut q = p.clone();
        q.remove(0).unwrap();
        assert_eq!(
            save(&dir, "pick_place", &q, false),
            Err(ProgramFileError::Exists {
                name: "pick_place".into()
            })
        );
        assert_eq!(load(&dir, "pick_place").unwrap(), p, "overwritten silently");
        save(&dir, "pick_place", &q, true).unwrap();
        assert_eq!(load(&dir, "pick_place").unwrap(), q);
        // only *.csv with a valid name; no temporary files left
        std::fs::write(dir.join("notes.txt"), "x").unwrap();
        std::fs::write(dir.join("bad name.csv"), "x").unwrap();
        std::fs::create_dir(dir.join("sub.csv")).unwrap();
        assert_eq!(list_programs(&dir), ["a-first", "pick_place"]);
        let files = std::fs::read_dir(&dir).unwrap().count();
        assert_eq!(files, 5, "no temporary file left behind");
        // errors name the program, never the path
        let e = load(&dir, "missing").unwrap_err().to_string();
        assert!(e.starts_with("cannot read program missing:"), "{e}");
        assert!(!e.contains(dir.to_str().unwrap()), "{e}");
        assert!(load(&dir, "../programs/pick_place").is_err());
        assert!(save(&dir, "a/b", &p, false).is_err());
        let mut bad = p.clone();
        bad.points[0].gripper = Some(7.0);
        let e = save(&dir, "bad", &bad, false).unwrap_err().to_string();
        assert!(e.starts_with("program bad: P1: gripper"), "{e}");
        assert!(!dir.join("bad.csv").exists());
        std::fs::write(dir.join("broken.csv"), "0.2,0,0.15,,0\n0.2,x,0.15,,0\n").unwrap();
        let e = load(&dir, "broken").unwrap_err().to_string();
        assert_eq!(e, "program broken: line 2: y `x` is not a number");
        let big = "#".repeat(usize::try_from(MAX_FILE_BYTES).unwrap() + 1);
        std::fs::write(dir.join("big.csv"), big).unwrap();
        assert!(load(&dir, "big")
            .unwrap_err()
            .to_string()
            .contains("larger than"));
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_a_symlink_or_a_device_is_refused_at_once_not_read() {
        let tmp = TempDir::new("special");
        let dir = tmp.0.clone();
        // a FIFO with no writer: opening it for reading would wait for ever
        nix::unistd::mkfifo(&dir.join("fifo.csv"), nix::sys::stat::Mode::S_IRWXU).unwrap();
        assert_eq!(
            load(&dir, "fifo"),
            Err(ProgramFileError::NotRegular {
                name: "fifo".into()
            })
        );
        // a symbolic link to a file outside: not followed, its content never shown
        std::fs::write(tmp.0.join("secret.txt"), "root:x:0:0:secret line\n").unwrap();
        std::os::unix::fs::symlink(tmp.0.join("secret.txt"), dir.join("link.csv")).unwrap();
        let e = load(&dir, "link").unwrap_err();
        assert_eq!(
            e,
            ProgramFileError::NotRegular {
                name: "link".into()
            }
        );
        assert!(!e.to_string().contains("secret"));
        std::os::unix::fs::symlink("/dev/zero", dir.join("zero.csv")).unwrap();
        assert!(matches!(
            load(&dir, "zero"),
            Err(ProgramFileError::NotRegular { .. })
        ));
        // none of them is listed; saving over the link replaces the link, not its target
        assert!(list_programs(&dir).is_empty(), "{:?}", list_programs(&dir));
        save(&dir, "link", &three(), true).unwrap();
        assert_eq!(
            std::fs::read_to_string(tmp.0.join("secret.txt")).unwrap(),
            "root:x:0:0:secret line\n"
        );
        assert_eq!(load(&dir, "link").unwrap(), three());
    }

    #[test]
    fn a_formula_name_is_saved_as_text_and_read_back_as_it_was() {
        let tmp = TempDir::new("formula");
        let mut p = three();
        let names = ["=HYPERLINK(\"http://evil.example\")", "+1", "@SUM(A1)"];
        for (i, name) in names.iter().enumerate() {
            p.rename(i, name).unwrap();
        }
        save(&tmp.0, "f", &p, false).unwrap();
        let text = std::fs::read_to_string(tmp.0.join("f.csv")).unwrap();
        for line in text.lines().skip(1) {
            let cell = line.splitn(7, ',').nth(6).unwrap();
            assert!(cell.starts_with('\''), "a formula cell: {line}");
        }
        assert_eq!(load(&tmp.0, "f").unwrap(), p);
    }

    // ---- the player ----

    const A: [f64; 3] = [0.2, 0.0, 0.15];
    const B: [f64; 3] = [0.2, 0.0, 0.09];
    const C: [f64; 3] = [0.18, 0.05, 0.12];

    fn ms(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    fn program(points: Vec<ProgramPoint>) -> Program {
        Program { points }
    }

    /// A player of `points`, started at `t0`.
    fn start(points: Vec<ProgramPoint>, looping: bool, t0: Instant) -> Player {
        Player::start(&program(points), looping, t0).unwrap()
    }

    /// A player of A (dwelling `dwell_s`) then B, started at `t0`, that has sent A; the
    /// arm arrived at A at `arrived_ms` when that is given.
    fn a_then_b(dwell_s: f64, looping: bool, t0: Instant, arrived_ms: Option<u64>) -> Player {
        let points = vec![point("", A, None, dwell_s, None), to(B)];
        let mut pl = start(points, looping, t0);
        assert_eq!(pl.step(t0, None), [target(0, A)]);
        if let Some(at) = arrived_ms {
            pl.step(ms(t0, at), Some(A));
        }
        pl
    }

    /// The state of a player with no failure.
    fn state(index: usize, phase: PlayerPhase, loops: usize) -> PlayerState {
        PlayerState {
            index,
            phase,
            loops,
            reason: None,
        }
    }

    /// Point `index`'s target on `xyz_target`.
    fn target(index: usize, xyz: [f64; 3]) -> PlayerAction {
        PlayerAction::Target {
            index,
            xyz,
            line: false,
        }
    }

    /// Point `index`'s target on `xyz_line_target`.
    fn line_target(index: usize, xyz: [f64; 3]) -> PlayerAction {
        PlayerAction::Target {
            index,
            xyz,
            line: true,
        }
    }

    fn arrived(index: usize) -> PlayerAction {
        PlayerAction::Arrived { index }
    }

    #[test]
    fn start_refuses_an_empty_or_invalid_program() {
        let t0 = Instant::now();
        assert!(Player::start(&Program::default(), false, t0)
            .unwrap_err()
            .contains("no points"));
        let bad = program(vec![point("", A, None, -1.0, None)]);
        assert!(Player::start(&bad, true, t0).is_err());
    }

    #[test]
    fn three_points_with_dwell_play_in_order() {
        let t0 = Instant::now();
        let mut pl = start(
            vec![
                point("", A, None, 0.5, None),
                point("", B, None, 1.0, None),
                to(C),
            ],
            false,
            t0,
        );
        assert_eq!(pl.next_wakeup(), Some(t0), "due at once");
        assert_eq!(pl.state().phase, PlayerPhase::Moving);
        assert_eq!(pl.step(t0, Some(C)), [target(0, A)]);
        assert_eq!(pl.next_wakeup(), Some(t0 + MOVE_TIMEOUT));
        assert_eq!(pl.step(ms(t0, 100), Some([0.2, 0.01, 0.15])), []);
        assert_eq!(pl.step(ms(t0, 200), Some(A)), [arrived(0)]);
        assert_eq!(pl.state(), state(0, PlayerPhase::Dwelling, 0));
        assert_eq!(pl.step(ms(t0, 699), None), []);
        assert_eq!(pl.step(ms(t0, 700), None), [target(1, B)]);
        assert_eq!(pl.step(ms(t0, 900), Some(B)), [arrived(1)]);
        assert_eq!(pl.step(ms(t0, 1899), Some(B)), []);
        assert_eq!(pl.step(ms(t0, 1900), Some(B)), [target(2, C)]);
        // no dwell: the end comes with the arrival
        assert_eq!(
            pl.step(ms(t0, 2500), Some(C)),
            [arrived(2), PlayerAction::Finished]
        );
        assert_eq!(pl.state().phase, PlayerPhase::Finished);
        assert_eq!(pl.state().index, 2);
        assert!(!pl.is_running());
        assert_eq!(pl.next_wakeup(), None);
        assert_eq!(pl.step(ms(t0, 5000), Some(A)), []);
    }

    #[test]
    fn arrival_counts_only_within_tolerance_and_after_the_target() {
        let t0 = Instant::now();
        let mut pl = start(vec![to(A), to(A)], false, t0);
        // already there when it starts: the observation of the step that sent the target
        // does not count
        assert_eq!(pl.step(t0, Some(A)), [target(0, A)]);
        let off = |d: f64| [A[0] + d, A[1], A[2]];
        assert_eq!(pl.step(ms(t0, 10), Some(off(0.0021))), []);
        assert_eq!(
            pl.step(ms(t0, 20), Some([A[0] + 0.0015, A[1] + 0.0015, A[2]])),
            [],
            "2.12 mm off"
        );
        assert_eq!(pl.step(ms(t0, 30), None), [], "no observation");
        assert_eq!(
            pl.step(ms(t0, 40), Some(off(-0.0019))),
            [arrived(0), target(1, A)]
        );
        assert_eq!(
            pl.step(ms(t0, 50), Some(off(0.0))),
            [arrived(1), PlayerAction::Finished]
        );
    }

    #[test]
    fn each_target_carries_its_points_move_kind_in_order_with_nothing_between() {
        let t0 = Instant::now();
        let mut pl = start(vec![line(A), line(B), to(C), joint(A), line(B)], false, t0);
        assert_eq!(pl.step(t0, None), [line_target(0, A)]);
        assert_eq!(pl.state().phase, PlayerPhase::Moving);
        assert_eq!(pl.next_wakeup(), Some(t0 + MOVE_TIMEOUT));
        assert_eq!(
            pl.step(ms(t0, 10), Some(A)),
            [arrived(0), line_target(1, B)]
        );
        assert_eq!(
            pl.step(ms(t0, 20), Some(B)),
            [arrived(1), target(2, C)],
            "no mode: xyz_target"
        );
        assert_eq!(pl.step(ms(t0, 30), Some(C)), [arrived(2), target(3, A)]);
        assert_eq!(
            pl.step(ms(t0, 40), Some(A)),
            [arrived(3), line_target(4, B)],
            "from joint to line: no step between"
        );
        assert_eq!(
            pl.step(ms(t0, 50), Some(B)),
            [arrived(4), PlayerAction::Finished]
        );
    }

    #[test]
    fn a_base_mode_is_for_the_points_without_one() {
        let t0 = Instant::now();
        let mut pl =
            start(vec![to(A), joint(B), line(C)], false, t0).with_base_mode(MoveMode::Line);
        assert_eq!(pl.step(t0, None), [line_target(0, A)], "--line");
        assert_eq!(
            pl.step(ms(t0, 10), Some(A)),
            [arrived(0), target(1, B)],
            "its own"
        );
        assert_eq!(
            pl.step(ms(t0, 20), Some(B)),
            [arrived(1), line_target(2, C)]
        );
    }

    #[test]
    fn the_gripper_is_set_after_arrival_then_the_dwell() {
        let t0 = Instant::now();
        let mut pl = start(
            vec![
                point("", A, Some(0.25), 2.0, None),
                point("", B, Some(1.0), 0.0, None),
            ],
            false,
            t0,
        );
        assert_eq!(pl.step(t0, None), [target(0, A)]);
        assert_eq!(
            pl.step(ms(t0, 500), Some(A)),
            [arrived(0), PlayerAction::Gripper(0.25)]
        );
        assert_eq!(pl.next_wakeup(), Some(ms(t0, 2500)));
        assert_eq!(pl.step(ms(t0, 2500), None), [target(1, B)]);
        assert_eq!(
            pl.step(ms(t0, 3000), Some(B)),
            [
                arrived(1),
                PlayerAction::Gripper(1.0),
                PlayerAction::Finished
            ]
        );
    }

    #[test]
    fn next_wakeup_is_the_end_of_the_dwell() {
        let t0 = Instant::now();
        let mut pl = a_then_b(1.5, false, t0, Some(300));
        assert_eq!(pl.state().phase, PlayerPhase::Dwelling);
        assert_eq!(pl.next_wakeup(), Some(ms(t0, 1800)));
        // observations during the dwell change nothing
        assert_eq!(pl.step(ms(t0, 1000), Some(B)), []);
        assert_eq!(pl.next_wakeup(), Some(ms(t0, 1800)));
        assert_eq!(pl.step(ms(t0, 1800), None), [target(1, B)]);
        assert_eq!(pl.next_wakeup(), Some(ms(t0, 1800) + MOVE_TIMEOUT));
    }

    #[test]
    fn looping_starts_over_at_point_0() {
        let t0 = Instant::now();
        let mut pl = start(vec![line(A), joint(B)], true, t0);
        assert_eq!(pl.step(t0, None), [line_target(0, A)]);
        assert_eq!(pl.step(ms(t0, 10), Some(A)), [arrived(0), target(1, B)]);
        // after the last point: point 0 again, in its own kind, no Finished, the loop
        // counted
        assert_eq!(
            pl.step(ms(t0, 30), Some(B)),
            [arrived(1), line_target(0, A)]
        );
        assert_eq!(pl.state(), state(0, PlayerPhase::Moving, 1));
        assert_eq!(pl.step(ms(t0, 50), Some(A)), [arrived(0), target(1, B)]);
        // a single point looping without dwell: one target a step, never a busy loop
        let one = program(vec![to(A)]);
        let mut pl = Player::start(&one, true, t0).unwrap();
        assert_eq!(pl.step(t0, Some(A)), [target(0, A)]);
        assert_eq!(pl.step(ms(t0, 10), Some(A)), [arrived(0), target(0, A)]);
        assert_eq!(pl.next_wakeup(), Some(ms(t0, 10) + MOVE_TIMEOUT));
        assert_eq!(pl.state().loops, 1);
    }

    #[test]
    fn stop_ends_the_playback() {
        let t0 = Instant::now();
        let mut pl = a_then_b(5.0, true, t0, Some(100));
        pl.stop();
        assert_eq!(pl.state(), state(0, PlayerPhase::Stopped, 0));
        assert_eq!(pl.next_wakeup(), None);
        assert_eq!(pl.step(ms(t0, 6000), Some(B)), []);
        pl.refused("late");
        assert_eq!(pl.step(ms(t0, 7000), None), []);
        assert_eq!(pl.state().phase, PlayerPhase::Stopped);
    }

    #[test]
    fn a_point_not_reached_in_time_fails() {
        let t0 = Instant::now();
        let mut pl = a_then_b(0.0, false, t0, Some(100));
        let sent = ms(t0, 100);
        assert_eq!(pl.next_wakeup(), Some(sent + MOVE_TIMEOUT));
        assert_eq!(
            pl.step(sent + MOVE_TIMEOUT - Duration::from_millis(1), Some(A)),
            []
        );
        let out = pl.step(sent + MOVE_TIMEOUT, None);
        let [PlayerAction::Failed { index: 1, reason }] = out.as_slice() else {
            panic!("{out:?}")
        };
        assert!(reason.contains("did not arrive"), "{reason}");
        let s = pl.state();
        assert_eq!((s.index, s.phase), (1, PlayerPhase::Failed));
        assert!(s.reason.unwrap().contains("did not arrive"));
        assert_eq!(pl.next_wakeup(), None);
        assert_eq!(pl.step(sent + MOVE_TIMEOUT * 2, Some(B)), []);
    }

    #[test]
    fn a_refused_target_fails() {
        let t0 = Instant::now();
        let mut pl = a_then_b(0.0, false, t0, None);
        pl.refused("the line leaves the workspace");
        assert_eq!(pl.state().phase, PlayerPhase::Failed);
        assert_eq!(pl.next_wakeup(), Some(t0), "the failure is due at once");
        assert_eq!(
            pl.step(ms(t0, 10), Some(A)),
            [PlayerAction::Failed {
                index: 0,
                reason: "refused: the line leaves the workspace".into()
            }],
            "a failure ends it: no arrival"
        );
        assert_eq!(pl.step(ms(t0, 20), Some(A)), []);
        assert_eq!(pl.next_wakeup(), None);
    }
}
