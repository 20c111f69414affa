//! Whether a process joins the graph with DDS-Security, and as which enclave. The variables are ROS 2's
//! (rcl's `rcl/src/rcl/security.c`), so the same environment secures these nodes and any ROS 2 node beside
//! them; where rcl would read a slip as "off" these nodes fail closed instead, and say so:
//!
//! - `ROS_SECURITY_ENABLE`: `true` turns security on, unset or empty leaves it off and changes nothing.
//!   rcl enables only on exactly `true`; here `TRUE`, `1`, `yes`, `on` (any case, spaces trimmed) also
//!   enable, `false`, `0`, `no`, `off` leave it off, and any other value refuses to start.
//! - `ROS_SECURITY_STRATEGY`: unset, empty or `Permissive` — a process that cannot find its enclave starts
//!   without security and says why. `Enforce`, and any other value (`enforce`, a typo) — it refuses to
//!   start. rcl reads everything but exactly `Enforce` as permissive.
//! - `ROS_SECURITY_KEYSTORE`: the keystore (`softcontact security create-keystore`).
//! - The enclave: `ROS_SECURITY_ENCLAVE_OVERRIDE` if set and not empty, else `--enclave NAME` of the
//!   command line (`--ros-args --enclave`), else `/`. Its folder is the keystore's `enclaves/NAME`.
//!
//! Every place where this reading differs from rcl's is a warning ([`Environment::warnings`]): a ROS 2
//! node started with the same environment would run without security, or without enforcement.

use std::path::{Path, PathBuf};

/// What `ROS_SECURITY_STRATEGY` asks for when the enclave cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    Enforce,
    Permissive,
}

/// The `ROS_SECURITY_*` variables of a process.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Environment {
    pub enable: Option<String>,
    pub strategy: Option<String>,
    pub keystore: Option<String>,
    pub enclave_override: Option<String>,
}

impl Environment {
    /// This process's variables.
    pub fn from_process() -> Self {
        Self::from_lookup(|name| std::env::var(name).ok())
    }

    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> Self {
        Environment {
            enable: get("ROS_SECURITY_ENABLE"),
            strategy: get("ROS_SECURITY_STRATEGY"),
            keystore: get("ROS_SECURITY_KEYSTORE"),
            enclave_override: get("ROS_SECURITY_ENCLAVE_OVERRIDE"),
        }
    }

    /// Whether security is asked for; an error for a value that is neither yes nor no.
    pub fn enabled(&self) -> Result<bool, String> {
        let Some(value) = self.enable.as_deref() else { return Ok(false) };
        match value.trim().to_ascii_lowercase().as_str() {
            "true" | "1" | "yes" | "on" => Ok(true),
            "" | "false" | "0" | "no" | "off" => Ok(false),
            _ => Err(format!(
                "ROS_SECURITY_ENABLE={value:?} is neither true nor false: not starting (set it to `true` for \
                 DDS-Security, unset it for none)"
            )),
        }
    }

    pub fn strategy(&self) -> Strategy {
        match self.strategy.as_deref().map(str::trim) {
            None | Some("") => Strategy::Permissive,
            Some(s) if s.eq_ignore_ascii_case("permissive") => Strategy::Permissive,
            Some(_) => Strategy::Enforce,
        }
    }

    /// Where this reading differs from rcl's: what a ROS 2 node given the same environment would do.
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if let Some(value) = self.enable.as_deref().filter(|v| *v != "true" && self.enabled() == Ok(true)) {
            warnings.push(format!(
                "ROS_SECURITY_ENABLE={value:?} read as true; rcl enables security only on exactly `true`: a \
                 ROS 2 node given this environment runs without DDS-Security"
            ));
        }
        if let Some(value) =
            self.strategy.as_deref().filter(|v| *v != "Enforce" && self.strategy() == Strategy::Enforce)
        {
            warnings.push(format!(
                "ROS_SECURITY_STRATEGY={value:?} read as Enforce; rcl enforces only on exactly `Enforce`: a ROS 2 \
                 node given this environment would start without security where its enclave is missing"
            ));
        }
        warnings
    }
}

/// How the process joins the graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decision {
    /// Security is not asked for: as before.
    Off,
    /// With the enclave `name`'s identity and permissions from `dir`.
    Secure { name: String, dir: PathBuf },
    /// Asked for, the enclave unusable, Permissive: without security, for the reason given.
    Unsecured { why: String },
}

/// The files an enclave folder holds (`softcontact security create-enclave`, sros2).
pub const ENCLAVE_FILES: [&str; 6] =
    ["cert.pem", "key.pem", "identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s", "permissions.p7s"];

/// Decides for `env` and the command line's `--enclave` (if any). An error is the refusal to start
/// under `Enforce`, saying what is missing and how to make it.
pub fn decide(env: &Environment, enclave_arg: Option<&str>) -> Result<Decision, String> {
    if !env.enabled()? {
        return Ok(Decision::Off);
    }
    let name = match (env.enclave_override.as_deref(), enclave_arg) {
        (Some(o), _) if !o.is_empty() => o.to_owned(),
        (_, Some(a)) => a.to_owned(),
        _ => "/".to_owned(),
    };
    let found = enclave(env.keystore.as_deref(), &name);
    match (found, env.strategy()) {
        (Ok(dir), _) => Ok(Decision::Secure { name, dir }),
        (Err(why), Strategy::Permissive) => Ok(Decision::Unsecured { why }),
        (Err(why), Strategy::Enforce) => Err(format!(
            "ROS_SECURITY_ENABLE with ROS_SECURITY_STRATEGY=Enforce, and {why}: not starting \
             (make it with `softcontact security create-keystore DIR --enclaves`, or `create-enclave DIR {name}`)"
        )),
    }
}

/// The folder of enclave `name` in the keystore, with every file an enclave needs.
fn enclave(keystore: Option<&str>, name: &str) -> Result<PathBuf, String> {
    let keystore = match keystore {
        Some(k) if !k.is_empty() => Path::new(k),
        _ => return Err("ROS_SECURITY_KEYSTORE is not set".into()),
    };
    softcontact_security::check_enclave_name(name).map_err(|e| e.to_string())?;
    let dir = softcontact_security::enclave_dir(keystore, name);
    if !dir.is_dir() {
        return Err(format!("enclave {name} has no folder {} in the keystore", dir.display()));
    }
    let missing: Vec<&str> = ENCLAVE_FILES.into_iter().filter(|f| !dir.join(f).is_file()).collect();
    if !missing.is_empty() {
        return Err(format!("enclave {name} ({}) lacks {}", dir.display(), missing.join(", ")));
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_security::{Grant, create_enclave, create_keystore};

    fn env(vars: &[(&str, &str)]) -> Environment {
        Environment::from_lookup(|n| vars.iter().find(|(k, _)| *k == n).map(|(_, v)| v.to_string()))
    }

    #[test]
    fn without_ros_security_enable_nothing_changes() {
        for off in [None, Some(""), Some("false"), Some(" FALSE "), Some("0"), Some("no"), Some("off")] {
            let e = Environment {
                enable: off.map(str::to_owned),
                strategy: Some("Enforce".into()),
                keystore: Some("/nowhere".into()),
                enclave_override: None,
            };
            assert_eq!(decide(&e, Some("/user")), Ok(Decision::Off), "{off:?}");
            assert!(e.warnings().is_empty(), "{off:?}: {:?}", e.warnings());
        }
    }

    #[test]
    fn a_slip_in_the_variables_fails_closed_and_is_said() {
        let missing_keystore = |enable: &str, strategy: &str| {
            env(&[
                ("ROS_SECURITY_ENABLE", enable),
                ("ROS_SECURITY_STRATEGY", strategy),
                ("ROS_SECURITY_KEYSTORE", "/nowhere"),
            ])
        };
        for enable in ["TRUE", "True", "1", "true ", "yes", "ON"] {
            let e = missing_keystore(enable, "Enforce");
            let refusal = decide(&e, Some("/user")).unwrap_err();
            assert!(refusal.contains("not starting"), "{enable:?}: {refusal}");
            assert!(e.warnings().iter().any(|w| w.contains("exactly `true`")), "{enable:?}: {:?}", e.warnings());
        }
        for strategy in ["enforce", "Enforce ", "ENFORCE", "Enforced", "strict"] {
            let e = missing_keystore("true", strategy);
            assert_eq!(e.strategy(), Strategy::Enforce, "{strategy:?}");
            assert!(decide(&e, Some("/user")).unwrap_err().contains("not starting"), "{strategy:?}");
            assert!(e.warnings().iter().any(|w| w.contains("exactly `Enforce`")), "{strategy:?}: {:?}", e.warnings());
        }
        for permissive in ["", "Permissive", "permissive"] {
            assert_eq!(missing_keystore("true", permissive).strategy(), Strategy::Permissive, "{permissive:?}");
        }
        for garbage in ["maybe", "truee", "2"] {
            let refusal = decide(&missing_keystore(garbage, "Permissive"), None).unwrap_err();
            assert!(refusal.contains("neither true nor false"), "{garbage:?}: {refusal}");
        }
        assert!(missing_keystore("true", "Enforce").warnings().is_empty());
    }

    #[test]
    fn the_enclave_comes_from_the_override_then_the_command_line_then_slash() {
        let dir = tempfile::tempdir().unwrap();
        let ks = dir.path().to_str().unwrap();
        create_keystore(dir.path(), 0).unwrap();
        for name in ["/", "/user", "/lwr_control"] {
            create_enclave(dir.path(), name, &Grant::everything(), 0).unwrap();
        }
        let on = [("ROS_SECURITY_ENABLE", "true"), ("ROS_SECURITY_STRATEGY", "Enforce"), ("ROS_SECURITY_KEYSTORE", ks)];
        let secure = |name: &str, dir: PathBuf| Ok(Decision::Secure { name: name.into(), dir });
        assert_eq!(decide(&env(&on), None), secure("/", dir.path().join("enclaves")));
        assert_eq!(decide(&env(&on), Some("/user")), secure("/user", dir.path().join("enclaves/user")));
        let mut with_override = on.to_vec();
        with_override.push(("ROS_SECURITY_ENCLAVE_OVERRIDE", "/lwr_control"));
        assert_eq!(
            decide(&env(&with_override), Some("/user")),
            secure("/lwr_control", dir.path().join("enclaves/lwr_control"))
        );
        with_override.pop();
        with_override.push(("ROS_SECURITY_ENCLAVE_OVERRIDE", ""));
        assert_eq!(decide(&env(&with_override), Some("/user")), secure("/user", dir.path().join("enclaves/user")));
    }

    #[test]
    fn enforce_refuses_without_a_usable_enclave_and_permissive_runs_unsecured_saying_why() {
        let dir = tempfile::tempdir().unwrap();
        let ks = dir.path().to_str().unwrap().to_owned();
        create_keystore(dir.path(), 0).unwrap();
        create_enclave(dir.path(), "/user", &Grant::everything(), 0).unwrap();
        std::fs::remove_file(dir.path().join("enclaves/user/permissions.p7s")).unwrap();
        let keystore = [("ROS_SECURITY_KEYSTORE", ks.as_str())];
        let cases: [(&[(&str, &str)], _, _); 4] = [
            (&[], Some("/user"), "ROS_SECURITY_KEYSTORE is not set"),
            (&keystore, Some("/stranger"), "has no folder"),
            (&keystore, Some("/user"), "lacks permissions.p7s"),
            (&keystore, Some("user"), "must start with `/`"),
        ];
        for (vars, arg, why) in cases {
            let mut enforce = vec![("ROS_SECURITY_ENABLE", "true"), ("ROS_SECURITY_STRATEGY", "Enforce")];
            enforce.extend(vars.iter().copied());
            let e = decide(&env(&enforce), arg).unwrap_err();
            assert!(e.contains(why) && e.contains("not starting") && e.contains("softcontact security"), "{e}");
            let mut permissive = vec![("ROS_SECURITY_ENABLE", "true")];
            permissive.extend(vars.iter().copied());
            match decide(&env(&permissive), arg).unwrap() {
                Decision::Unsecured { why: w } => assert!(w.contains(why), "{w}"),
                other => panic!("{other:?}"),
            }
        }
    }
}
