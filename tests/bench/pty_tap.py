#!/usr/bin/env python3
"""pty_tap: a pseudo-terminal in front of a serial device, logging every byte with the
time it crossed. Used by the end-to-end benchmark (e2e.py) to time "the first byte of a
command on the serial port" without changing serial_node or the device.

    pty_tap.py DEVICE LINK LOG

* DEVICE: the device end the host would normally open (the virtual Arduino's pty, or the
  simavr harness's pty; both are ptys whose other end the device holds).
* LINK: created here, a symlink to the slave end of a new pty: give it to serial_node as
  its `port`. The tap keeps its own handle on that slave (raw mode), as servo_sim does,
  so nothing is echoed before serial_node configures the port.
* Every chunk read from serial_node (host -> device) or from the device (device -> host)
  is forwarded at once and logged as `h NS HEX` or `d NS HEX`, NS = CLOCK_REALTIME in
  nanoseconds taken when select() returned (the same clock as ROS header stamps and
  Fast DDS reception timestamps on this machine). The log is kept in memory and written
  at exit: a write to a busy disk must not hold the forwarding up.
* Runs at SCHED_FIFO priority 1 when allowed (as linkem.py does), so the time a byte is
  seen is not the time a loaded scheduler got round to it.
* Prints `ready` once LINK exists. SIGTERM/SIGINT: flush the log, remove LINK, exit 0.
"""
import gc
import os
import select
import signal
import sys
import time
import tty


def main():
    if len(sys.argv) != 4:
        sys.stderr.write(__doc__)
        return 2
    device, link, log_path = sys.argv[1:]
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        realtime = True
    except (PermissionError, OSError):
        realtime = False
    dev = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(dev)
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    if os.path.lexists(link):
        os.unlink(link)
    os.symlink(os.ttyname(slave), link)
    log = [f"# pty_tap device={device} link={link} realtime={int(realtime)}\n"]
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    gc.disable()  # no collector pauses while forwarding (nothing here makes cycles)
    print("ready", flush=True)

    def forward(src, dst, tag):
        t = time.time_ns()
        try:
            data = os.read(src, 4096)
        except BlockingIOError:
            return
        except OSError:  # the other side closed (EIO on a pty master without a slave)
            time.sleep(0.01)
            return
        if not data:
            return
        view = memoryview(data)
        while view:
            try:
                n = os.write(dst, view)
                view = view[n:]
            except BlockingIOError:
                select.select([], [dst], [], 0.01)
            except OSError:
                break
        log.append((tag, t, data))

    while not stop:
        try:
            ready, _, _ = select.select([master, dev], [], [], 0.2)
        except InterruptedError:
            continue
        if master in ready:
            forward(master, dev, "h")
        if dev in ready:
            forward(dev, master, "d")
    with open(log_path, "w") as f:
        f.write(log[0])
        f.writelines(f"{tag} {t} {data.hex()}\n" for tag, t, data in log[1:])
    if os.path.islink(link):
        os.unlink(link)
    return 0


if __name__ == "__main__":
    sys.exit(main())
