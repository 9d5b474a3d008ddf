//! Pseudo-terminal pairs for simulated serial devices: the device side reads and answers on the
//! master; a client opens the slave's path as it would a USB serial port.

use serialport::{SerialPort, TTYPort};
use std::os::fd::AsRawFd;
use std::time::Duration;

/// A pseudo-terminal pair whose master reads time out after `read_timeout`: (master, slave,
/// the slave's path). Both ends are close-on-exec, so a process started while the device runs
/// does not keep its port alive after the device goes (as an unplugged module's does not).
pub fn pair(read_timeout: Duration) -> std::io::Result<(TTYPort, TTYPort, String)> {
    let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::other)?;
    for fd in [master.as_raw_fd(), slave.as_raw_fd()] {
        // SAFETY: fcntl on descriptors this function owns.
        unsafe { libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC) };
    }
    master
        .set_timeout(read_timeout)
        .map_err(std::io::Error::other)?;
    let path = slave
        .name()
        .ok_or_else(|| std::io::Error::other("pseudo-terminal has no name"))?;
    Ok((master, slave, path))
}
