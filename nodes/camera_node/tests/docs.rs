//! docs/parameters.md's camera_node table is what `camera_node::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&camera_node::spec()) {
        panic!("{why}");
    }
}
