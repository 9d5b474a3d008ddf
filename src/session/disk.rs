//! The file system under a session: free space (checked before firing), space reserved for a
//! recording's frames (so a disk that fills cannot cut it short), and directory fsyncs (so a
//! created or renamed file survives a power cut).

use std::fs::File;
use std::path::{Path, PathBuf};

/// Free and total bytes on the file system that holds `dir` (or the nearest existing parent:
/// the sessions directory is created by the first recording).
pub fn disk_space(dir: &Path) -> Result<(u64, u64), String> {
    let mut probe = if dir.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        dir.to_path_buf()
    };
    while !probe.exists() {
        match probe.parent() {
            Some(p) if !p.as_os_str().is_empty() => probe = p.to_path_buf(),
            _ => {
                probe = PathBuf::from(".");
                break;
            }
        }
    }
    let c_path = std::ffi::CString::new(probe.as_os_str().as_encoded_bytes())
        .map_err(|_| format!("{}: path contains a NUL byte", probe.display()))?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::zeroed();
    // SAFETY: c_path is a valid NUL-terminated string and st points to writable memory of the
    // right type; statvfs fills it on success.
    let rc = unsafe { libc::statvfs(c_path.as_ptr(), st.as_mut_ptr()) };
    if rc != 0 {
        return Err(format!(
            "{}: statvfs: {}",
            probe.display(),
            std::io::Error::last_os_error()
        ));
    }
    // SAFETY: statvfs returned 0, so the struct is initialised.
    let st = unsafe { st.assume_init() };
    Ok(statvfs_bytes(&st))
}

/// (free to unprivileged users, total) bytes.
// c_ulong and fsblkcnt_t are not u64 on every target.
#[allow(clippy::unnecessary_cast)]
fn statvfs_bytes(st: &libc::statvfs) -> (u64, u64) {
    let frag = st.f_frsize as u64;
    (st.f_bavail as u64 * frag, st.f_blocks as u64 * frag)
}

/// Makes `file` at least `len` bytes long on disk, with real blocks behind it (not a sparse
/// hole), so later writes up to `len` cannot fail for want of space. File systems that cannot
/// reserve (EOPNOTSUPP, e.g. some network file systems) leave the file as it is: the free-space
/// check before firing is then the only guard.
pub fn reserve(file: &File, len: u64) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let Ok(len) = libc::off_t::try_from(len) else {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{len} bytes is beyond the file size this system allows"),
        ));
    };
    // SAFETY: the descriptor is open for writing for the duration of the call.
    let rc = unsafe { libc::posix_fallocate(file.as_raw_fd(), 0, len) };
    match rc {
        0 => Ok(()),
        libc::EOPNOTSUPP | libc::EINVAL => Ok(()),
        e => Err(std::io::Error::from_raw_os_error(e)),
    }
}

/// fsyncs a directory, so the entries created or renamed in it are on disk.
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}
