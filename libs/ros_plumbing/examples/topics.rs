//! Print the contract ([`ros_plumbing::topics::all`], [`ros_plumbing::topics::CALLABLES`]):
//! `--json` as `tests/data/topics.json` holds it (what the Python tests read),
//! `--markdown` as docs/topics.md's topic table.
//!
//! ```sh
//! cargo run -q -p ros_plumbing --example topics -- --json > tests/data/topics.json
//! ```

use ros_plumbing::topics;
use std::process::ExitCode;

fn main() -> ExitCode {
    let all = topics::all();
    match std::env::args().nth(1).as_deref() {
        Some("--json") => print!("{}", topics::json(&all, topics::CALLABLES)),
        Some("--markdown") => print!("{}", topics::markdown_table(&all)),
        _ => {
            eprintln!("usage: topics --json | --markdown");
            return ExitCode::from(2);
        }
    }
    ExitCode::SUCCESS
}
