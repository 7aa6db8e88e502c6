//! docs/parameters.md's serial_node table is what `serial_node::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&serial_node::spec()) {
        panic!("{why}");
    }
}
