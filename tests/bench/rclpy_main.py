"""The end of a benchmark's own rclpy node process (probe_proc.py, seed_ik_node.py)."""
import contextlib


@contextlib.contextmanager
def spinning(node):
    """The body spins `node` (rclpy initialised for it); Ctrl-C (SIGINT) or rclpy's
    external shutdown (SIGTERM) ends that quietly, and then the node and rclpy are shut
    down."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    try:
        yield
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
