//! Batch slots: the shared-memory blocks that every worker of a session writes its envs'
//! results into, so that a whole batch is one contiguous `[num_envs, ...]` array per field
//! whatever the number of workers.
//!
//! iceoryx2 gives every publisher its own data segment, so samples from several workers can
//! never form one contiguous block; a slot is therefore a POSIX shared-memory object of the
//! client's, which its workers map read-write. Requests and responses still travel as
//! iceoryx2 samples (the actions, the command, the slot to write, the info section); only the
//! results live here.
//!
//! Lifetime: the client's [`SlotPool`] creates slots and lends them out as [`SlotLease`]s (the
//! base object of the numpy arrays that view them). A slot is written again only when no
//! lease is left, so arrays a user keeps never change; when every slot is lent the pool grows
//! up to its memory cap, then falls back to a scratch slot that is never lent (the caller
//! copies out of it). Names are removed from `/dev/shm` when the pool closes, by a worker that
//! sees its owner die, or by the next pool of the same namespace once the creator is dead.

use crate::DataPlaneError;
use crate::layout::{BatchLayout, ResponseBlocks, ResponseBlocksMut};
use serde::{Deserialize, Serialize};
use std::ffi::CString;
use std::sync::Arc;

/// Most lendable slots a session has (the scratch slot's index is one past them).
pub const MAX_SLOTS: usize = 1024;

/// Where a session's slots live: shared-memory objects `/<prefix>slots_<session>_ns<pidns>_<k>`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SlotsName {
    /// The iceoryx2 namespace prefix of the session (keeps namespaces apart).
    pub prefix: String,
    /// The session id; starts with the creating process's pid (`<pid>-...`).
    pub session: String,
    /// The creating process's PID namespace (its `/proc/self/ns/pid` inode): its pid means
    /// something only there, so only a process of the same namespace judges it stale.
    #[serde(default)]
    pub pid_ns: u64,
}

/// This process's PID namespace: the inode of `/proc/self/ns/pid` (0 if unreadable).
pub fn pid_namespace() -> u64 {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self/ns/pid").map_or(0, |m| m.ino())
}

impl SlotsName {
    /// The slots of session `session` in namespace `prefix`, created by this process.
    pub fn new(prefix: impl Into<String>, session: impl Into<String>) -> SlotsName {
        SlotsName {
            prefix: prefix.into(),
            session: session.into(),
            pid_ns: pid_namespace(),
        }
    }

    /// The file name (in `/dev/shm`) of every slot of this session, without the index.
    fn stem(&self) -> String {
        format!("{}slots_{}_ns{:x}_", self.prefix, self.session, self.pid_ns)
    }

    fn path(&self, index: u32) -> Result<CString, DataPlaneError> {
        CString::new(format!("/{}{index}", self.stem())).map_err(|_| {
            DataPlaneError::Protocol(format!("slot name `{}` holds a NUL byte", self.stem()))
        })
    }

    /// Removes every slot name of this session from `/dev/shm` (mappings stay valid). Used by
    /// the pool when it closes and by a worker whose owner died without closing it.
    pub fn unlink_all(&self) {
        let stem = self.stem();
        for name in shm_names() {
            if name.starts_with(&stem) {
                unlink(&name);
            }
        }
    }
}

fn shm_names() -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|dir| {
            dir.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

fn unlink(file_name: &str) {
    if let Ok(path) = CString::new(format!("/{file_name}")) {
        // SAFETY: a valid NUL-terminated name; unlinking has no memory effects.
        unsafe { libc::shm_unlink(path.as_ptr()) };
    }
}

fn os_error(what: &'static str) -> DataPlaneError {
    DataPlaneError::Ipc {
        what,
        detail: std::io::Error::last_os_error().to_string(),
    }
}

/// Removes the slots of sessions in `prefix`'s namespace whose creating process is gone (a
/// client killed together with its workers, before anyone could clean up). Only slots made in
/// this process's PID namespace are judged: a pid of another namespace (a container sharing
/// `/dev/shm`) names another process here, so those are left alone, as are names of another
/// form.
pub fn remove_stale_slots(prefix: &str) {
    let stem = format!("{prefix}slots_");
    let ours = format!("ns{:x}", pid_namespace());
    for name in shm_names() {
        let Some(rest) = name.strip_prefix(&stem) else {
            continue;
        };
        if !rest.split('_').any(|part| part == ours) {
            continue;
        }
        let pid = rest
            .split(['-', '_'])
            .next()
            .and_then(|p| p.parse::<i32>().ok());
        // SAFETY: signal 0 only checks that the process exists.
        if let Some(pid) = pid
            && unsafe { libc::kill(pid, 0) } != 0
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
        {
            unlink(&name);
        }
    }
}

/// Sizes the new object `fd` to `len` bytes and reserves its pages now: `ftruncate` alone
/// leaves a sparse object, and a `/dev/shm` that cannot back it kills the first process that
/// touches a missing page with SIGBUS (a worker, far from the cause).
fn reserve(fd: libc::c_int, len: usize) -> Result<(), DataPlaneError> {
    let Ok(off_len) = libc::off_t::try_from(len) else {
        return Err(DataPlaneError::NoSpace {
            what: "a batch slot",
            needed: len as u64,
            free: shm_free_bytes(),
        });
    };
    // SAFETY: fd is ours; the object is new and empty (zero-filled once sized).
    if unsafe { libc::ftruncate(fd, off_len) } != 0 {
        return Err(os_error("size batch slot"));
    }
    if len == 0 {
        return Ok(());
    }
    // SAFETY: fd is ours; posix_fallocate returns an error number and sets no errno.
    match unsafe { libc::posix_fallocate(fd, 0, off_len) } {
        0 => Ok(()),
        libc::ENOSPC | libc::ENOMEM | libc::EFBIG => Err(DataPlaneError::NoSpace {
            what: "a batch slot",
            needed: len as u64,
            free: shm_free_bytes(),
        }),
        // A file system that cannot reserve (none that backs `/dev/shm` on Linux): keep the
        // sparse object, as before.
        libc::EOPNOTSUPP | libc::EINVAL => Ok(()),
        code => Err(DataPlaneError::Ipc {
            what: "reserve batch slot",
            detail: std::io::Error::from_raw_os_error(code).to_string(),
        }),
    }
}

/// Bytes free in `/dev/shm` for an unprivileged process (0 when it cannot be read).
pub fn shm_free_bytes() -> u64 {
    // SAFETY: a valid NUL-terminated path and a valid out-pointer.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c"/dev/shm".as_ptr(), &mut st) } != 0 {
        return 0;
    }
    (st.f_bavail as u64).saturating_mul(st.f_frsize as u64)
}

/// A mapped shared-memory object.
struct Mapping {
    ptr: *mut u8,
    len: usize,
}

// SAFETY: the mapping is plain memory owned by this value; which parts may be written or
// read at a time is governed by the request/response protocol, not by the pointer's thread.
unsafe impl Send for Mapping {}
// SAFETY: as above; shared references only read, and only rows no worker is writing.
unsafe impl Sync for Mapping {}

impl Mapping {
    /// Opens (or, with `create`, creates) the object `path` of `len` bytes and maps it.
    fn map(path: &CString, len: usize, create: bool) -> Result<Mapping, DataPlaneError> {
        let flags = if create {
            libc::O_RDWR | libc::O_CREAT | libc::O_EXCL
        } else {
            libc::O_RDWR
        };
        // SAFETY: a valid NUL-terminated name; returns a new fd or -1.
        let fd = unsafe { libc::shm_open(path.as_ptr(), flags, 0o600) };
        if fd < 0 {
            return Err(os_error(if create {
                "create batch slot"
            } else {
                "open batch slot"
            }));
        }
        let sized = if create {
            match reserve(fd, len) {
                Ok(()) => true,
                Err(err) => {
                    // SAFETY: fd is ours and not used after this; the name is ours to remove.
                    unsafe {
                        libc::close(fd);
                        libc::shm_unlink(path.as_ptr());
                    }
                    return Err(err);
                }
            }
        } else {
            // SAFETY: fd is ours and `st` is a valid out-pointer.
            let mut st: libc::stat = unsafe { std::mem::zeroed() };
            unsafe { libc::fstat(fd, &mut st) == 0 && st.st_size as usize >= len }
        };
        if !sized {
            let err = os_error("size batch slot");
            // SAFETY: fd is ours and not used after this.
            unsafe { libc::close(fd) };
            if create {
                // SAFETY: as in `unlink`.
                unsafe { libc::shm_unlink(path.as_ptr()) };
            }
            return Err(err);
        }
        // SAFETY: a fresh shared read-write mapping of `len` bytes of the object; the fd can be
        // closed once mapped.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len.max(1),
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                fd,
                0,
            )
        };
        let err = (ptr == libc::MAP_FAILED).then(|| os_error("map batch slot"));
        // SAFETY: fd is ours and not used after this.
        unsafe { libc::close(fd) };
        match err {
            Some(err) => {
                if create {
                    // SAFETY: as in `unlink`.
                    unsafe { libc::shm_unlink(path.as_ptr()) };
                }
                Err(err)
            }
            None => Ok(Mapping {
                ptr: ptr.cast(),
                len,
            }),
        }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: ptr/len are the mapping made in `map`, unmapped once, here.
        unsafe { libc::munmap(self.ptr.cast(), self.len.max(1)) };
    }
}

/// Where each side of each channel says that it is blocked, so the other side rings (sends
/// an iceoryx2 notification, a syscall) only then: while both sides spin, a round trip costs
/// no syscall. One cache line per flag; a `u32` each, shared by the session's processes.
pub struct Doorbells {
    map: Mapping,
    channels: usize,
}

/// Bytes between two flags (one cache line each, so two sides never share a line).
const BELL_STRIDE: usize = 64;

impl Doorbells {
    fn path(name: &SlotsName) -> Result<CString, DataPlaneError> {
        CString::new(format!("/{}bells", name.stem()))
            .map_err(|_| DataPlaneError::Protocol("slot name holds a NUL byte".into()))
    }

    /// Creates the flags of `channels` channels (the client, before starting its workers).
    pub fn create(name: &SlotsName, channels: usize) -> Result<Arc<Doorbells>, DataPlaneError> {
        remove_stale_slots(&name.prefix);
        let map = Mapping::map(&Self::path(name)?, channels * 2 * BELL_STRIDE, true)?;
        Ok(Arc::new(Doorbells { map, channels }))
    }

    /// Opens the client's flags (a worker).
    pub fn open(name: &SlotsName, channels: usize) -> Result<Arc<Doorbells>, DataPlaneError> {
        let map = Mapping::map(&Self::path(name)?, channels * 2 * BELL_STRIDE, false)?;
        Ok(Arc::new(Doorbells { map, channels }))
    }

    /// The flags of channel `index`.
    pub fn bell(self: &Arc<Self>, index: usize) -> Result<Bell, DataPlaneError> {
        if index >= self.channels {
            return Err(DataPlaneError::Protocol(format!(
                "channel {index} of a session with {} channels",
                self.channels
            )));
        }
        Ok(Bell {
            bells: self.clone(),
            index,
        })
    }
}

/// One channel's two flags: the client's and the worker's "I am blocked".
#[derive(Clone)]
pub struct Bell {
    bells: Arc<Doorbells>,
    index: usize,
}

/// A side of a channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The client (sends requests).
    Client,
    /// The worker (sends responses).
    Worker,
}

impl Bell {
    /// The flag of `side`: non-zero while that side is blocked on its listener.
    pub fn flag(&self, side: Side) -> &std::sync::atomic::AtomicU32 {
        let offset = (2 * self.index + usize::from(side == Side::Worker)) * BELL_STRIDE;
        // SAFETY: inside the mapping (`bell` checked the index), 64-byte aligned (page-aligned
        // mapping, stride 64), and only ever accessed atomically by every process.
        unsafe {
            &*self
                .bells
                .map
                .ptr
                .add(offset)
                .cast::<std::sync::atomic::AtomicU32>()
        }
    }
}

/// One slot: a whole batch's results, laid out by a [`BatchLayout`].
pub struct Slot {
    index: u32,
    lendable: bool,
    layout: BatchLayout,
    map: Mapping,
}

impl std::fmt::Debug for Slot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Slot")
            .field("index", &self.index)
            .field("lendable", &self.lendable)
            .field("bytes", &self.layout.size())
            .finish()
    }
}

/// A slot kept by someone other than the pool (a numpy array's base object): while it lives,
/// the slot is not written again and stays mapped.
pub type SlotLease = Arc<Slot>;

impl Slot {
    /// Its index in the session (what requests name).
    pub fn index(&self) -> u32 {
        self.index
    }

    /// Whether it may be lent (the scratch slot may not: results in it must be copied).
    pub fn lendable(&self) -> bool {
        self.lendable
    }

    /// The results of envs `first..first + n`, viewed in place.
    ///
    /// Only rows whose results have arrived (a response naming this slot was received for
    /// them) and that no request in flight writes may be viewed; the session guarantees it.
    pub fn rows(&self, first: usize, n: usize) -> ResponseBlocks<'_> {
        // SAFETY: the mapping holds `layout.size()` bytes; the rows are not being written (the
        // caller's protocol guarantee above).
        let bytes = unsafe { std::slice::from_raw_parts(self.map.ptr, self.layout.size()) };
        self.layout.rows(bytes, first, n)
    }

    /// The rows of envs `first..first + n`, for writing results that arrived another way (a
    /// remote hub's message).
    ///
    /// # Safety
    /// No one else may read or write these rows while the blocks live (the results are being
    /// made: the slot is not lent and no worker was asked to write these rows).
    pub unsafe fn rows_mut(&self, first: usize, n: usize) -> ResponseBlocksMut<'_> {
        // SAFETY: the mapping holds `layout.size()` bytes, 8-byte aligned (page aligned);
        // exclusive as the caller guarantees.
        unsafe { self.layout.rows_mut(self.map.ptr, first, n) }
    }

    /// Marks env `env`'s episode truncated (a restarted worker's envs).
    ///
    /// # Safety
    /// No worker may be writing the row and no one else reading it (the results are being
    /// made: the worker has answered and the slot is not lent).
    pub unsafe fn set_truncated(&self, env: usize) {
        assert!(
            env < self.layout.num_envs,
            "env {env} of {}",
            self.layout.num_envs
        );
        // SAFETY: inside the mapping (checked above); exclusive as the caller guarantees.
        unsafe { self.map.ptr.add(self.layout.truncated + env).write(1) };
    }
}

/// The client's slots of one session.
pub struct SlotPool {
    name: SlotsName,
    layout: BatchLayout,
    slots: Vec<Arc<Slot>>,
    scratch: Option<Arc<Slot>>,
    max_slots: usize,
    current: usize,
    owner_pid: u32,
    closed: bool,
}

impl SlotPool {
    /// A pool for `layout`, holding at most `max_bytes` of lendable slots (at least two).
    /// Removes slots that dead sessions of the namespace left behind.
    pub fn new(name: SlotsName, layout: BatchLayout, max_bytes: usize) -> SlotPool {
        remove_stale_slots(&name.prefix);
        let max_slots = (max_bytes / layout.size().max(1)).clamp(2, MAX_SLOTS);
        SlotPool {
            name,
            layout,
            slots: Vec::new(),
            scratch: None,
            max_slots,
            current: 0,
            owner_pid: std::process::id(),
            closed: false,
        }
    }

    /// Slots created so far (lendable ones; the scratch slot is not counted).
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether no slot was created yet.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The slot at `index` (as requests name it).
    pub fn get(&self, index: u32) -> Option<&Arc<Slot>> {
        if index == self.scratch_index() {
            return self.scratch.as_ref();
        }
        self.slots.get(index as usize)
    }

    fn scratch_index(&self) -> u32 {
        self.max_slots as u32
    }

    fn create(&self, index: u32, lendable: bool) -> Result<Arc<Slot>, DataPlaneError> {
        let map = Mapping::map(&self.name.path(index)?, self.layout.size(), true)?;
        Ok(Arc::new(Slot {
            index,
            lendable,
            layout: self.layout,
            map,
        }))
    }

    /// The slot the next request's results go to: the current one unless it is lent, else
    /// one that is not lent, else a new one while under the cap, else the scratch slot. Never
    /// waits for a lease to end.
    pub fn writable(&mut self) -> Result<Arc<Slot>, DataPlaneError> {
        let free = |s: &Arc<Slot>| Arc::strong_count(s) == 1;
        if self.slots.get(self.current).is_some_and(free) {
            return Ok(self.slots[self.current].clone());
        }
        if let Some(i) = self.slots.iter().position(free) {
            self.current = i;
            return Ok(self.slots[i].clone());
        }
        if self.slots.len() < self.max_slots {
            let slot = self.create(self.slots.len() as u32, true)?;
            self.slots.push(slot.clone());
            self.current = self.slots.len() - 1;
            return Ok(slot);
        }
        if self.scratch.is_none() {
            self.scratch = Some(self.create(self.scratch_index(), false)?);
        }
        Ok(self.scratch.clone().expect("created above"))
    }

    /// Removes the slot names from `/dev/shm`. Mappings (and arrays viewing them) stay valid
    /// until their last lease is gone. Only the creating process does it (not a forked child).
    pub fn close(&mut self) {
        if !self.closed && std::process::id() == self.owner_pid {
            self.closed = true;
            self.name.unlink_all();
        }
    }
}

impl Drop for SlotPool {
    fn drop(&mut self) {
        self.close();
    }
}

/// A worker's mappings of its session's slots, opened when a request first names one.
pub struct SlotMap {
    name: SlotsName,
    layout: BatchLayout,
    maps: Vec<Option<Mapping>>,
}

impl SlotMap {
    /// No slot mapped yet.
    pub fn new(name: SlotsName, layout: BatchLayout) -> SlotMap {
        SlotMap {
            name,
            layout,
            maps: Vec::new(),
        }
    }

    /// The blocks of envs `first..first + n` of slot `index`, for writing.
    ///
    /// # Safety
    /// No one else may read or write these rows until the response that announces them is
    /// sent (the protocol: the client names a slot for these rows in one request at a time,
    /// and views them only after the response).
    pub unsafe fn rows_mut(
        &mut self,
        index: u32,
        first: usize,
        n: usize,
    ) -> Result<ResponseBlocksMut<'_>, DataPlaneError> {
        let i = index as usize;
        if i > MAX_SLOTS {
            return Err(DataPlaneError::Protocol(format!(
                "request names batch slot {index}; slots go up to {MAX_SLOTS}"
            )));
        }
        if self.maps.len() <= i {
            self.maps.resize_with(i + 1, || None);
        }
        if self.maps[i].is_none() {
            self.maps[i] = Some(Mapping::map(
                &self.name.path(index)?,
                self.layout.size(),
                false,
            )?);
        }
        let map = self.maps[i].as_ref().expect("mapped above");
        // SAFETY: the mapping holds `layout.size()` bytes and the caller guarantees these rows
        // are ours alone until the response is sent.
        Ok(unsafe { self.layout.rows_mut(map.ptr, first, n) })
    }

    /// The names of the session's slots (to remove them when the owner died).
    pub fn name(&self) -> &SlotsName {
        &self.name
    }
}

#[cfg(test)]
mod stale_tests {
    use super::*;

    #[test]
    fn only_slots_of_dead_owners_in_this_pid_namespace_are_removed() {
        let prefix = format!("stale_test_{}_", std::process::id());
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let ours = format!("ns{:x}", pid_namespace());
        let names = [
            format!("{prefix}slots_{dead}-0-0_{ours}_0"),
            format!("{prefix}slots_{dead}-0-0_ns1_0"),
            format!("{prefix}slots_{dead}-0-0_0"),
            format!("{prefix}slots_{}-0-0_{ours}_0", std::process::id()),
        ];
        for n in &names {
            std::fs::write(format!("/dev/shm/{n}"), b"").unwrap();
        }
        remove_stale_slots(&prefix);
        let left: Vec<bool> = names
            .iter()
            .map(|n| std::path::Path::new(&format!("/dev/shm/{n}")).exists())
            .collect();
        for n in &names {
            let _ = std::fs::remove_file(format!("/dev/shm/{n}"));
        }
        assert_eq!(
            left,
            [false, true, true, true],
            "removed: a dead owner's of this namespace; kept: another namespace's, an old name, a live owner's"
        );
    }
}
