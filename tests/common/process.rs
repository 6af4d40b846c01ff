//! Processes a test starts, ended by the test: also when it fails, and with every process
//! they started themselves (the `rerun` entry point is a Python script that starts the viewer
//! binary; killing the script alone leaves the viewer running, re-parented).

use std::process::{Child, Command};

/// A child started in a process group of its own; dropping it kills the whole group and reaps
/// the child.
pub struct Reaped(pub Child);

impl Reaped {
    /// Start `cmd` as the leader of a new process group.
    pub fn spawn(cmd: &mut Command) -> std::io::Result<Self> {
        #[cfg(unix)]
        std::os::unix::process::CommandExt::process_group(cmd, 0);
        cmd.spawn().map(Self)
    }

    /// The process group's id (the child's pid).
    pub fn group(&self) -> u32 {
        self.0.id()
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        // `kill -KILL -- -PGID` signals every process of the group, grandchildren included.
        let _ = Command::new("kill").args(["-KILL", "--", &format!("-{}", self.0.id())]).status();
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The processes of group `pgid` still alive (from `/proc/*/stat`; zombies not counted).
pub fn group_members(pgid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else { continue };
        // `pid (comm) state ppid pgrp ...`: comm may hold spaces, so split after its `)`.
        let Some((_, rest)) = stat.rsplit_once(')') else { continue };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        if fields.first() != Some(&"Z") && fields.get(2).and_then(|g| g.parse::<u32>().ok()) == Some(pgid) {
            out.push(pid);
        }
    }
    out
}
