//! docs/topics.md's tables are the contract: its topics ([`ros_plumbing::topics::all`])
//! and its actions and services ([`ros_plumbing::topics::CALLABLES`]).

use ros_plumbing::feedback::ReasonCode;
use ros_plumbing::{docs, topics};

#[test]
fn the_topics_page_is_the_contract() {
    if let Err(why) = docs::check_section(
        &docs::repo_root().join("docs/topics.md"),
        "topics",
        &topics::markdown_table(&topics::all()),
        "cargo test -p ros_plumbing --test docs",
    ) {
        panic!("{why}");
    }
}

#[test]
fn the_topics_page_lists_the_actions_and_services() {
    if let Err(why) = docs::check_section(
        &docs::repo_root().join("docs/topics.md"),
        "actions and services",
        &topics::callables_table(topics::CALLABLES),
        "cargo test -p ros_plumbing --test docs",
    ) {
        panic!("{why}");
    }
}

#[test]
fn the_topics_page_lists_every_reason_code_in_order() {
    let path = docs::repo_root().join("docs/topics.md");
    let page = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let table =
        docs::section(&page, "reason codes").unwrap_or_else(|e| panic!("docs/topics.md: {e}"));
    let listed: Vec<&str> = table
        .lines()
        .skip(2)
        .filter_map(|row| row.strip_prefix("| `")?.split('`').next())
        .collect();
    let codes: Vec<&str> = ReasonCode::ALL.iter().map(|c| c.code()).collect();
    assert_eq!(
        listed, codes,
        "docs/topics.md's reason code table should list ros_plumbing::feedback::ReasonCode::ALL, \
         in order, one row each (written by hand: the meanings are the variants' doc comments)"
    );
}
