//! A campaign's child processes (`hitl plan`, `hitl run`, `hitl eval`) never outlive it, and the
//! campaign alone decides when they stop:
//!
//! - each child runs in a process group of its own, so a terminal's Ctrl-C reaches the campaign
//!   only, and the campaign hands it on ([`interrupt_all`]) to every child it is waiting for;
//! - each child asks the kernel for SIGHUP when the campaign dies (`PR_SET_PDEATHSIG`), however
//!   it dies (`kill -9` included): `hitl run` then makes the controlled stop Ctrl-C makes
//!   (SIGTERM would end it on the spot), `hitl plan` and `hitl eval` end. Not SIGINT: the kernel
//!   sends the signal again each time the child passes from a dying campaign thread to the next,
//!   and a run counts SIGINTs as presses (the third abandons its stop); it takes any number of
//!   SIGHUPs as one request;
//! - the children's pids are known only while they can be signalled: a child is reaped and
//!   removed under the same lock [`interrupt_all`] signals under, so a reused pid is never hit.

#![allow(unsafe_code)]

use std::io;
use std::os::unix::process::CommandExt;
use std::process::{Command, ExitStatus};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

/// The children being waited for (each leads its own process group).
static CHILDREN: Mutex<Vec<u32>> = Mutex::new(Vec::new());

/// Set (under the [`CHILDREN`] lock) once Ctrl-C was handed on: a child started after that gets
/// it at once, so none slips between the campaign's check and its start.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// How often a waiting thread looks whether its child ended.
const POLL: Duration = Duration::from_millis(50);

/// Start `cmd` in a process group of its own, bound to end with this process, and wait for it.
pub fn run(mut cmd: Command) -> io::Result<ExitStatus> {
    let parent = std::process::id() as libc::pid_t;
    cmd.process_group(0);
    // SAFETY: the closure runs in the child between fork and exec, where only async-signal-safe
    // calls are allowed: it calls prctl(2) and getppid(2), both async-signal-safe, touches no
    // lock and allocates nothing (`last_os_error` and `from_raw_os_error` only wrap an errno).
    // PR_SET_PDEATHSIG fires when the thread that forked the child ends; that thread is the one
    // waiting for the child below, which lives until the child has ended (or the process dies).
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGHUP as libc::c_ulong) != 0 {
                return Err(io::Error::last_os_error());
            }
            // The campaign died before the request took effect: its signal will never come.
            if libc::getppid() != parent {
                return Err(io::Error::from_raw_os_error(libc::ESRCH));
            }
            Ok(())
        });
    }
    let mut child = {
        let mut list = CHILDREN.lock().unwrap_or_else(PoisonError::into_inner);
        let child = cmd.spawn()?;
        list.push(child.id());
        if INTERRUPTED.load(Ordering::SeqCst) {
            interrupt(child.id());
        }
        child
    };
    loop {
        {
            let mut list = CHILDREN.lock().unwrap_or_else(PoisonError::into_inner);
            let ended = child.try_wait();
            if !matches!(ended, Ok(None)) {
                list.retain(|&p| p != child.id());
            }
            if let Some(status) = ended? {
                return Ok(status);
            }
        }
        std::thread::sleep(POLL);
    }
}

/// Hand SIGINT to every running child's process group (Ctrl-C on the campaign).
pub fn interrupt_all() {
    let list = CHILDREN.lock().unwrap_or_else(PoisonError::into_inner);
    INTERRUPTED.store(true, Ordering::SeqCst);
    for &pid in list.iter() {
        interrupt(pid);
    }
}

/// SIGINT to the process group of `pid`, a listed child; call with the [`CHILDREN`] lock held.
fn interrupt(pid: u32) {
    // SAFETY: kill(2) takes plain integers and touches no memory of ours. `pid` is a listed
    // child, so not yet reaped (a child leaves the list under the lock the caller holds, before
    // `try_wait` hands its status back): its process group id is still its own, not reused.
    unsafe {
        libc::kill(-(pid as libc::pid_t), libc::SIGINT);
    }
}
