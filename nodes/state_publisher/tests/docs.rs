//! docs/parameters.md's state_publisher table is what `state_publisher::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&state_publisher::spec()) {
        panic!("{why}");
    }
}
