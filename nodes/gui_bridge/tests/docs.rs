//! docs/parameters.md's gui_bridge table is what `gui_bridge::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&gui_bridge::spec()) {
        panic!("{why}");
    }
}
