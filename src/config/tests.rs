use super::*;

#[test]
fn secret_never_prints() {
    let config = Config {
        auth_token: Some(Secret::new("hunter2")),
        ..Config::default()
    };
    let shown = format!("{config:?} {}", Secret::new("hunter2"));
    assert!(!shown.contains("hunter2"), "{shown}");
    assert!(shown.contains("[redacted]"));
}

#[test]
fn layers_file_then_env_then_flags() {
    figment::Jail::expect_with(|jail| {
        jail.create_file(
            "c.toml",
            "bind = \"127.0.0.1:1\"\nworkers = 3\nmax_attempts = 7\n",
        )?;
        jail.set_env("CHOREO_BIND", "127.0.0.1:2");
        jail.set_env("CHOREO_DATA_DIR", "/tmp/x");
        let overrides = Overrides {
            data_dir: Some("/tmp/y".into()),
            ..Overrides::default()
        };
        let c = Config::load(Some(Path::new("c.toml")), &overrides).map_err(|e| e.to_string())?;
        assert_eq!(c.bind, "127.0.0.1:2");
        assert_eq!(c.data_dir, PathBuf::from("/tmp/y"));
        assert_eq!(c.workers, 3);
        assert_eq!(c.max_attempts, 7);
        Ok(())
    });
}

#[test]
fn retention_days_takes_fractions_and_refuses_nothing_to_keep() {
    figment::Jail::expect_with(|jail| {
        let c = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .map_err(|e| e.to_string())?;
        assert_eq!(c.retention(), None, "unset keeps everything");
        jail.set_env("CHOREO_RETENTION_DAYS", "0.5");
        let c = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .map_err(|e| e.to_string())?;
        assert_eq!(
            c.retention(),
            Some(std::time::Duration::from_secs(12 * 3600))
        );
        for bad in ["0", "-1", "1e300"] {
            jail.set_env("CHOREO_RETENTION_DAYS", bad);
            let err = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
                .expect_err(bad)
                .to_string();
            // Named as the setting, or as its variable when it is not a number at all.
            assert!(
                err.to_ascii_lowercase().contains("retention_days"),
                "{bad}: {err}"
            );
        }
        Ok(())
    });
}

#[test]
fn database_url_picks_the_store_and_never_prints() {
    figment::Jail::expect_with(|jail| {
        let c = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .map_err(|e| e.to_string())?;
        assert_eq!(
            c.database().map_err(|e| e.to_string())?,
            Database::Sqlite(PathBuf::from("data/choreo.sqlite"))
        );
        jail.set_env("CHOREO_DATABASE_URL", "sqlite:///tmp/q.sqlite");
        let c = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .map_err(|e| e.to_string())?;
        assert_eq!(
            c.database().map_err(|e| e.to_string())?,
            Database::Sqlite(PathBuf::from("/tmp/q.sqlite"))
        );
        jail.set_env("CHOREO_DATABASE_URL", "postgres://u:hunter2@db:5432/choreo");
        let c = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .map_err(|e| e.to_string())?;
        assert!(matches!(c.database(), Ok(Database::Postgres(_))));
        assert!(!format!("{c:?} {:?}", c.database()).contains("hunter2"));
        jail.set_env("CHOREO_DATABASE_URL", "mysql://u:hunter2@db/choreo");
        let err = Config::load(Some(Path::new("missing.toml")), &Overrides::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("database_url") && !err.contains("hunter2"),
            "{err}"
        );
        Ok(())
    });
}

#[test]
fn webhook_settings_come_from_the_environment_and_the_secret_is_checked() {
    figment::Jail::expect_with(|jail| {
        let load = || Config::load(Some(Path::new("missing.toml")), &Overrides::default());
        jail.set_env(
            "CHOREO_WEBHOOK_ALLOWED_HOSTS",
            "Hooks.LAN:8443, 127.0.0.1:9000,[::1]:9",
        );
        jail.set_env(
            "CHOREO_WEBHOOK_SECRET",
            "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw",
        );
        let c = load().map_err(|e| e.to_string())?;
        assert_eq!(
            c.webhook_allowed_hosts,
            ["hooks.lan:8443", "127.0.0.1:9000", "[::1]:9"]
        );
        let key = c.webhook_key().map_err(|e| e.to_string())?;
        assert_eq!(key.map(|k| k.len()), Some(24));
        assert!(!format!("{c:?}").contains("MfKQ9r8"));
        for bad in [
            "MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw",
            "whsec_not base64!",
            "whsec_c2hvcnQ=",
        ] {
            jail.set_env("CHOREO_WEBHOOK_SECRET", bad);
            let err = load().unwrap_err().to_string();
            assert!(
                err.contains("webhook_secret") && !err.contains(bad),
                "{err}"
            );
        }
        jail.set_env(
            "CHOREO_WEBHOOK_SECRET",
            "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw",
        );
        jail.set_env("CHOREO_WEBHOOK_ALLOWED_HOSTS", "hooks.lan");
        let err = load().unwrap_err().to_string();
        assert!(err.contains("webhook_allowed_hosts"), "{err}");
        Ok(())
    });
}

#[test]
fn rejects_a_bad_bind_address() {
    figment::Jail::expect_with(|jail| {
        jail.set_env("CHOREO_BIND", "not an address");
        let err = Config::load(Some(Path::new("missing.toml")), &Overrides::default()).unwrap_err();
        assert!(err.to_string().contains("bind"), "{err}");
        Ok(())
    });
}
