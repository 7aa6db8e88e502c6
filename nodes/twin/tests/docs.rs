//! docs/parameters.md's twin table is what `twin::spec()` declares (without MuJoCo: the
//! parameters are the node's whether or not it was built with the physics).

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&twin::spec()) {
        panic!("{why}");
    }
}
