//! A real, throwaway PostgreSQL server for one test: `initdb` in a temp dir, `postgres` on a
//! random loopback port with its unix socket in the same dir, stopped and removed on drop.
//!
//! The binaries come from `$POSTGRES_BIN` or the newest `/usr/lib/postgresql/<v>/bin`
//! (Debian's `postgresql` package, installed by `scripts/setup.sh --test`). PostgreSQL refuses
//! to run as root, so as root the server runs as the `postgres` user (`setpriv`, which execs, so
//! the child we hold is the postmaster itself). A missing install fails the test, never skips it.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running server; dropping it stops the server and deletes its files.
pub struct Postgres {
    dir: tempfile::TempDir,
    child: Child,
    port: u16,
}

fn bin_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("POSTGRES_BIN") {
        return PathBuf::from(dir);
    }
    let mut versions: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| Some((e.file_name().to_str()?.parse().ok()?, e.path().join("bin"))))
        .filter(|(_, bin)| bin.join("initdb").is_file())
        .collect();
    versions.sort();
    match versions.pop() {
        Some((_, bin)) => bin,
        None => panic!(
            "PostgreSQL is not installed (no /usr/lib/postgresql/<version>/bin/initdb; set POSTGRES_BIN to override): \
             run `bash scripts/setup.sh --test` (CI={})",
            std::env::var("CI").unwrap_or_default()
        ),
    }
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

/// `bin` run as the `postgres` user when we are root, as ourselves otherwise.
fn command(bin: &Path) -> Command {
    if is_root() {
        let mut c = Command::new("setpriv");
        c.args([
            "--reuid=postgres",
            "--regid=postgres",
            "--init-groups",
            "--",
        ])
        .arg(bin);
        c
    } else {
        Command::new(bin)
    }
}

fn free_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a free port");
    listener.local_addr().expect("local addr").port()
}

impl Postgres {
    /// Initialises and starts a server; panics with the server's log when it does not come up.
    pub fn start() -> Self {
        let bin = bin_dir();
        let dir = tempfile::Builder::new()
            .prefix("choreo-pg-")
            .tempdir()
            .expect("tempdir");
        if is_root() {
            let status = Command::new("chown")
                .arg("postgres:postgres")
                .arg(dir.path())
                .status()
                .expect("chown");
            assert!(status.success(), "chown postgres {}", dir.path().display());
        }
        let data = dir.path().join("data");
        let out = command(&bin.join("initdb"))
            .arg("-D")
            .arg(&data)
            .args([
                "-U",
                "choreo",
                "--auth=trust",
                "-E",
                "UTF8",
                "--no-sync",
                "--no-instructions",
            ])
            .output()
            .expect("run initdb");
        assert!(
            out.status.success(),
            "initdb failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::File::create(dir.path().join("postgres.log")).expect("log file");
        if is_root() {
            let status = Command::new("chown")
                .arg("postgres:postgres")
                .arg(dir.path().join("postgres.log"))
                .status()
                .expect("chown");
            assert!(status.success());
        }
        let port = free_port();
        let child = Self::spawn(&bin, dir.path(), port);
        let mut server = Self { dir, child, port };
        server.wait_ready();
        server
    }

    /// Starts the postmaster on `port` over the data dir in `dir`.
    fn spawn(bin: &Path, dir: &Path, port: u16) -> Child {
        let log = std::fs::OpenOptions::new()
            .append(true)
            .open(dir.join("postgres.log"))
            .expect("log file");
        // Durability is not under test: no fsync makes each test's server start and run faster.
        command(&bin.join("postgres"))
            .arg("-D")
            .arg(dir.join("data"))
            .args([
                "-p",
                &port.to_string(),
                "-c",
                "listen_addresses=127.0.0.1",
                "-c",
                "fsync=off",
            ])
            .args([
                "-c",
                "synchronous_commit=off",
                "-c",
                "full_page_writes=off",
                "-c",
                "max_connections=200",
            ])
            .arg("-k")
            .arg(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("spawn postgres")
    }

    /// Stops the server as an operator would (`pg_ctl stop -m fast`, SIGINT: sessions are ended,
    /// then a checkpoint). Not SIGQUIT: with `synchronous_commit=off` a crash loses the last
    /// commits, the migrations among them.
    pub fn stop(&mut self) {
        Self::signal(&mut self.child, libc::SIGINT);
    }

    /// Starts the stopped server again, on the same port over the same data.
    pub fn restart(&mut self) {
        // The log must say "ready" anew: start it over.
        std::fs::write(self.dir.path().join("postgres.log"), b"").expect("truncate log");
        self.child = Self::spawn(&bin_dir(), self.dir.path(), self.port);
        self.wait_ready();
    }

    /// Sends `signal` to the postmaster and waits (bounded) for it to exit; kills it after 10 s.
    fn signal(child: &mut Child, signal: libc::c_int) {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        if let Ok(pid) = i32::try_from(child.id()) {
            // SAFETY: kill only sends a signal to our own child.
            unsafe {
                libc::kill(pid, signal);
            }
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    }

    fn wait_ready(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(Some(status)) = self.child.try_wait() {
                panic!("postgres exited ({status}): {}", self.log());
            }
            if std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok()
                && self
                    .dir
                    .path()
                    .join(format!(".s.PGSQL.{}", self.port))
                    .exists()
                && self.log().contains("ready to accept connections")
            {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "postgres not ready after 30 s: {}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The server's log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("postgres.log")).unwrap_or_default()
    }

    /// The TCP port.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// A URL of the default database, over TCP.
    pub fn url(&self) -> String {
        format!("postgres://choreo@127.0.0.1:{}/postgres", self.port)
    }

    /// A URL of the default database over the unix socket in the temp dir.
    pub fn socket_url(&self) -> String {
        format!(
            "postgres://choreo@localhost/postgres?host={}&port={}",
            self.dir.path().display(),
            self.port
        )
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        // SIGQUIT: immediate shutdown, the postmaster ends its backends and exits.
        Self::signal(&mut self.child, libc::SIGQUIT);
    }
}
