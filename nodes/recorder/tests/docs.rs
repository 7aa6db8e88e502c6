//! docs/parameters.md's recorder table is what `recorder::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&recorder::spec()) {
        panic!("{why}");
    }
}
