//! The reference tables of the `docs/` pages, rendered from the code that declares
//! them, and the check that a page still holds what the code renders.
//!
//! A generated table sits in its page between two markers,
//! `<!-- generated: NAME -->` and `<!-- end generated: NAME -->`. Each declaring crate
//! has a test (`tests/docs.rs`) that calls [`check_section`]: it fails when the page
//! differs from the code and says how to regenerate it, and with `EEZYBOT_BLESS=1` in
//! the environment it rewrites the section instead.
//!
//! Errors are plain sentences (`String`): they end up only in a failing test's message.
//!
//! # Examples
//! ```
//! use ros_plumbing::{docs, NodeSpec, ParamRange, ParamSpec, ParameterValue};
//! let spec = NodeSpec {
//!     name: "demo",
//!     description: "a demo node",
//!     usage: "",
//!     params: vec![ParamSpec::new("rate", ParameterValue::Double(50.0), "steps a second")
//!         .range(ParamRange::Double { min: 1.0, max: 500.0 })],
//! };
//! let table = docs::params_table(&spec);
//! assert!(table.contains("| `rate` | double | `50.0` | 1.0 … 500.0 | any time | steps a second |"));
//!
//! let page = "intro\n<!-- generated: demo -->\nold\n<!-- end generated: demo -->\nmore\n";
//! assert_eq!(docs::section(page, "demo"), Ok("old\n"));
//! let page = docs::replace_section(page, "demo", "new\n").unwrap();
//! assert_eq!(docs::section(&page, "demo"), Ok("new\n"));
//! ```

use crate::params::{ParamRange, ParamSpec};
use crate::NodeSpec;
use ros2_client::ParameterValue;
use std::fmt::Write as _;
use std::path::Path;

/// The environment variable that makes [`check_section`] rewrite a stale section.
pub const BLESS_VAR: &str = "EEZYBOT_BLESS";

/// The line that opens the generated section `name`.
pub fn begin_marker(name: &str) -> String {
    format!("<!-- generated: {name} -->")
}

/// The line that closes the generated section `name`.
pub fn end_marker(name: &str) -> String {
    format!("<!-- end generated: {name} -->")
}

/// A parameter's type as `ros2 param describe` names it.
fn type_text(v: &ParameterValue) -> &'static str {
    match v {
        ParameterValue::NotSet => "not set",
        ParameterValue::Boolean(_) => "bool",
        ParameterValue::Integer(_) => "integer",
        ParameterValue::Double(_) => "double",
        ParameterValue::String(_) => "string",
        ParameterValue::ByteArray(_) => "byte array",
        ParameterValue::BooleanArray(_) => "bool array",
        ParameterValue::IntegerArray(_) => "integer array",
        ParameterValue::DoubleArray(_) => "double array",
        ParameterValue::StringArray(_) => "string array",
    }
}

/// A value as it is written on the command line (`-p name:=VALUE`), in code quotes;
/// the empty string is `""`.
fn value_text(v: &ParameterValue) -> String {
    let inner = match v {
        ParameterValue::NotSet => "(not set)".to_string(),
        ParameterValue::Boolean(b) => b.to_string(),
        ParameterValue::Integer(i) => i.to_string(),
        ParameterValue::Double(d) => format!("{d:?}"),
        ParameterValue::String(s) if s.is_empty() => "\"\"".to_string(),
        ParameterValue::String(s) => s.clone(),
        ParameterValue::ByteArray(a) => format!("{a:?}"),
        ParameterValue::BooleanArray(a) => format!("{a:?}"),
        ParameterValue::IntegerArray(a) => format!("{a:?}"),
        ParameterValue::DoubleArray(a) => format!("{a:?}"),
        ParameterValue::StringArray(a) => format!("{a:?}"),
    };
    format!("`{}`", inner.replace('`', "'"))
}

/// What a parameter accepts beyond its type: its range and its constraints in words.
fn accepts_text(p: &ParamSpec) -> String {
    let range = match p.range {
        ParamRange::Any => None,
        ParamRange::Integer { min, max } => Some(format!("{min} … {max}")),
        ParamRange::Double { min, max } => Some(format!("{min:?} … {max:?}")),
    };
    let parts: Vec<String> = range
        .into_iter()
        .chain((!p.constraints.is_empty()).then(|| p.constraints.to_string()))
        .collect();
    if parts.is_empty() {
        "any".to_string()
    } else {
        parts.join("; ")
    }
}

/// Text made safe for one cell of a Markdown table: no line breaks, `|` escaped.
fn cell(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}

/// The parameter table of a node, one row per declared parameter in declaration order:
/// `| parameter | type | default | accepts | set | meaning |` (`set` is `at start` for a
/// read-only parameter, else `any time`).
pub fn params_table(spec: &NodeSpec) -> String {
    let mut s = String::from(
        "| parameter | type | default | accepts | set | meaning |\n|---|---|---|---|---|---|\n",
    );
    for p in &spec.params {
        let _ = writeln!(
            s,
            "| `{}` | {} | {} | {} | {} | {} |",
            p.name,
            type_text(&p.default),
            cell(&value_text(&p.default)),
            cell(&accepts_text(p)),
            if p.read_only { "at start" } else { "any time" },
            cell(p.description),
        );
    }
    s
}

/// Byte range of the body of section `name` in `text` (between the end of the begin
/// marker's line and the start of the end marker's line).
fn section_span(text: &str, name: &str) -> Result<(usize, usize), String> {
    let begin = begin_marker(name);
    let end = end_marker(name);
    let find_line = |marker: &str| -> Result<usize, String> {
        let mut found = text
            .match_indices(marker)
            .filter(|(i, _)| *i == 0 || text[..*i].ends_with('\n'))
            .map(|(i, _)| i);
        match (found.next(), found.next()) {
            (Some(i), None) => Ok(i),
            (None, _) => Err(format!("no line `{marker}`")),
            (Some(_), Some(_)) => Err(format!("`{marker}` is there more than once")),
        }
    };
    let b = find_line(&begin)?;
    let e = find_line(&end)?;
    let body_start = text[b..]
        .find('\n')
        .map(|i| b + i + 1)
        .ok_or_else(|| format!("nothing follows `{begin}`"))?;
    if e < body_start {
        return Err(format!("`{end}` comes before `{begin}`"));
    }
    Ok((body_start, e))
}

/// The body of the generated section `name` of `text`, without its markers.
pub fn section<'a>(text: &'a str, name: &str) -> Result<&'a str, String> {
    section_span(text, name).map(|(b, e)| &text[b..e])
}

/// `text` with the body of section `name` replaced by `body` (a newline is added if
/// `body` does not end with one); the markers and everything outside stay.
pub fn replace_section(text: &str, name: &str, body: &str) -> Result<String, String> {
    let (b, e) = section_span(text, name)?;
    let mut out = String::with_capacity(text.len() + body.len());
    out.push_str(&text[..b]);
    out.push_str(body);
    if !body.ends_with('\n') {
        out.push('\n');
    }
    out.push_str(&text[e..]);
    Ok(out)
}

/// Checks that section `name` of the page at `path` is `want`. With
/// `EEZYBOT_BLESS=1` in the environment a stale section is rewritten instead. The
/// error names the page and the section, shows what it should hold and says how to
/// regenerate it (`regenerate`, e.g. `cargo test -p compute_ik --test docs`).
pub fn check_section(path: &Path, name: &str, want: &str, regenerate: &str) -> Result<(), String> {
    let page = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let want = if want.ends_with('\n') {
        want.to_string()
    } else {
        format!("{want}\n")
    };
    let have = section(&page, name).map_err(|e| format!("{}: {e}", path.display()))?;
    if have == want {
        return Ok(());
    }
    if std::env::var(BLESS_VAR).is_ok_and(|v| v == "1") {
        let page = replace_section(&page, name, &want)?;
        return std::fs::write(path, page).map_err(|e| format!("{}: {e}", path.display()));
    }
    Err(format!(
        "{}: the section `{name}` differs from the code; regenerate it with\n  \
         {BLESS_VAR}=1 {regenerate}\nIt should read:\n\n{want}",
        path.display()
    ))
}

/// The page the parameter tables live in, relative to the repository.
pub const PARAMETERS_PAGE: &str = "docs/parameters.md";

/// The repository's root (this crate sits at `libs/ros_plumbing`).
pub fn repo_root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Checks the section `NODE parameters` of [`PARAMETERS_PAGE`] against
/// [`params_table`] of `spec`, as [`check_section`] does; the regenerate command is
/// `cargo test -p NODE --test docs`. Each node's `tests/docs.rs` calls it.
pub fn check_node_parameters(spec: &NodeSpec) -> Result<(), String> {
    check_section(
        &repo_root().join(PARAMETERS_PAGE),
        &format!("{} parameters", spec.name),
        &params_table(spec),
        &format!("cargo test -p {} --test docs", spec.name),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> NodeSpec {
        NodeSpec {
            name: "demo",
            description: "",
            usage: "",
            params: vec![
                ParamSpec::new(
                    "port",
                    ParameterValue::String(String::new()),
                    "the | device\n  or `mock`",
                )
                .read_only()
                .constraints("one of: a, b"),
                ParamSpec::new("baud", ParameterValue::Integer(115_200), "speed").range(
                    ParamRange::Integer {
                        min: 1200,
                        max: 1_000_000,
                    },
                ),
                ParamSpec::new("on", ParameterValue::Boolean(true), "switch"),
                ParamSpec::new("period", ParameterValue::Double(0.05), "s")
                    .range(ParamRange::Double {
                        min: 0.01,
                        max: 60.0,
                    })
                    .constraints("not zero"),
            ],
        }
    }

    #[test]
    fn params_table_renders_every_column() {
        let table = params_table(&spec());
        let rows: Vec<&str> = table.lines().collect();
        assert_eq!(rows.len(), 6, "{table}");
        assert_eq!(
            rows[0],
            "| parameter | type | default | accepts | set | meaning |"
        );
        assert_eq!(
            rows[2],
            "| `port` | string | `\"\"` | one of: a, b | at start | the \\| device or `mock` |"
        );
        assert_eq!(
            rows[3],
            "| `baud` | integer | `115200` | 1200 … 1000000 | any time | speed |"
        );
        assert_eq!(
            rows[4],
            "| `on` | bool | `true` | any | any time | switch |"
        );
        assert_eq!(
            rows[5],
            "| `period` | double | `0.05` | 0.01 … 60.0; not zero | any time | s |"
        );
    }

    #[test]
    fn every_row_has_six_cells() {
        for line in params_table(&spec()).lines() {
            let cells = line.replace("\\|", "").matches('|').count();
            assert_eq!(cells, 7, "{line}");
        }
    }

    const PAGE: &str = "# T\n<!-- generated: a -->\nold\nrows\n<!-- end generated: a -->\ntail\n";

    #[test]
    fn section_is_the_text_between_the_markers() {
        assert_eq!(section(PAGE, "a"), Ok("old\nrows\n"));
        let empty = "<!-- generated: a -->\n<!-- end generated: a -->\n";
        assert_eq!(section(empty, "a"), Ok(""));
    }

    #[test]
    fn replace_section_keeps_everything_outside() {
        let out = replace_section(PAGE, "a", "new").unwrap();
        assert_eq!(
            out,
            "# T\n<!-- generated: a -->\nnew\n<!-- end generated: a -->\ntail\n"
        );
    }

    #[test]
    fn a_missing_repeated_or_reversed_marker_is_an_error() {
        assert!(section(PAGE, "b")
            .unwrap_err()
            .contains("no line `<!-- generated: b -->`"));
        let twice = format!("{PAGE}{PAGE}");
        assert!(section(&twice, "a").unwrap_err().contains("more than once"));
        let reversed = "<!-- end generated: a -->\n<!-- generated: a -->\nx\n";
        assert!(section(reversed, "a").unwrap_err().contains("comes before"));
        // a marker quoted inside a line is not a marker
        let quoted = "see `<!-- generated: a -->`\n<!-- end generated: a -->\n";
        assert!(section(quoted, "a").is_err());
    }

    #[test]
    fn check_section_reports_a_stale_page_with_the_command() {
        let dir = std::env::temp_dir().join(format!("eezybot_docs_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("page.md");
        std::fs::write(&path, PAGE).unwrap();
        assert_eq!(
            check_section(&path, "a", "old\nrows", "cargo test -p x"),
            Ok(())
        );
        if std::env::var(BLESS_VAR).is_err() {
            let err =
                check_section(&path, "a", "new\n", "cargo test -p x --test docs").unwrap_err();
            assert!(
                err.contains("EEZYBOT_BLESS=1 cargo test -p x --test docs"),
                "{err}"
            );
            assert!(err.contains("It should read:\n\nnew\n"), "{err}");
            assert_eq!(
                std::fs::read_to_string(&path).unwrap(),
                PAGE,
                "the page is only read"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
