//! docs/topics.md's table is the topic contract, [`ros_plumbing::topics::all`].

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
