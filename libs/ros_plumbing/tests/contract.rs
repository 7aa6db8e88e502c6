//! The topic contract ([`ros_plumbing::topics`]) and its copies outside Rust cannot
//! drift: `tests/data/topics.json` (read by the Python tests) and the README's topic
//! table must be exactly what the table renders.

use ros_plumbing::topics;
use std::path::PathBuf;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(repo().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

#[test]
fn the_python_tests_read_the_same_topic_table() {
    let want = topics::json(&topics::all());
    assert!(
        read("tests/data/topics.json") == want,
        "tests/data/topics.json is stale; regenerate it:\n  \
         cargo run -q -p ros_plumbing --example topics -- --json > tests/data/topics.json"
    );
}

#[test]
fn the_readme_topic_table_is_the_contract() {
    let readme = read("README.md");
    let want = topics::markdown_table(&topics::all());
    assert!(
        readme.contains(&want),
        "README.md's topic table differs from ros_plumbing::topics; the table should read:\n\n{want}\n\
         (cargo run -q -p ros_plumbing --example topics -- --markdown)"
    );
}

#[test]
fn every_topic_of_the_contract_is_in_interfaces_md() {
    // shared/INTERFACES.md lives beside the repository when it is checked out with it
    let Ok(interfaces) = std::fs::read_to_string(repo().join("../shared/INTERFACES.md")) else {
        return;
    };
    for t in topics::all() {
        assert!(
            interfaces.contains(&format!("`{}`", t.name)),
            "{} is not in shared/INTERFACES.md",
            t.name
        );
        assert!(
            interfaces.contains(&t.type_name),
            "{}'s type {} is not in shared/INTERFACES.md",
            t.name,
            t.type_name
        );
    }
}
