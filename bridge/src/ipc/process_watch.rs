//! Watching the estimator process through a pidfd: readable once the process has
//! ended (a zombie included), whether or not it is our child, so a waiting request
//! notices its death within one wait slice instead of after the request timeout.

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

#[derive(Debug)]
pub(crate) struct ProcessWatch {
    pid: u32,
    fd: OwnedFd,
}

impl ProcessWatch {
    pub(crate) fn open(pid: u32) -> std::io::Result<Self> {
        let raw_pid = libc::pid_t::try_from(pid)
            .map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput))?;
        // SAFETY: pidfd_open takes a pid and flags and returns a new descriptor or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, raw_pid, 0) };
        if fd < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let fd = i32::try_from(fd).map_err(|_| std::io::Error::other("pidfd out of range"))?;
        // SAFETY: the kernel just gave us this descriptor; nobody else owns it.
        let fd = unsafe { OwnedFd::from_raw_fd(fd) };
        Ok(Self { pid, fd })
    }

    pub(crate) fn pid(&self) -> u32 {
        self.pid
    }

    /// True once the process has ended.
    pub(crate) fn has_exited(&self) -> bool {
        let mut p = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one pollfd we own, no waiting.
        let n = unsafe { libc::poll(&mut p, 1, 0) };
        n > 0 && (p.revents & (libc::POLLIN | libc::POLLHUP)) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sees_a_killed_process_end_even_before_it_is_reaped() {
        let mut child = std::process::Command::new("sleep")
            .arg("600")
            .spawn()
            .unwrap();
        let watch = ProcessWatch::open(child.id()).unwrap();
        assert!(!watch.has_exited());
        child.kill().unwrap();
        // Not reaped yet: a zombie. The pidfd turns readable when the process ends.
        let mut p = libc::pollfd {
            fd: watch.fd.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: as above; blocks until the kill has taken effect.
        assert_eq!(unsafe { libc::poll(&mut p, 1, 10_000) }, 1);
        assert!(watch.has_exited());
        child.wait().unwrap();
    }
}
