//! `softcontact security`: keystores for the secure graph, laid out as `ros2 security` lays them out
//! (`softcontact_security`), with each enclave's least-privilege permissions
//! (`softcontact_nodes::runtime::enclaves`).

use std::path::PathBuf;

use clap::Subcommand;
use softcontact_nodes::runtime::enclaves::{ENCLAVES, grant};
use softcontact_security::{Grant, create_enclave, create_keystore};

#[derive(Subcommand)]
pub enum SecurityCommand {
    /// A new keystore in DIR: a certificate authority (public/, private/) and sros2's governance, signed
    /// (enclaves/governance.p7s). With --enclaves, every enclave of the graph too.
    CreateKeystore {
        dir: PathBuf,
        /// Also create every enclave of the graph (`softcontact security list-enclaves`).
        #[arg(long)]
        enclaves: bool,
        /// The DDS domain the governance and permissions are for [default: ROS_DOMAIN_ID, else 0].
        #[arg(long)]
        domain: Option<u32>,
    },
    /// Enclave NAME in the keystore DIR: a key, a certificate from the keystore's authority, and the
    /// permissions of that enclave, signed. Run again, it re-signs the permissions and keeps the identity.
    CreateEnclave {
        dir: PathBuf,
        /// One of the graph's enclaves (`softcontact security list-enclaves`), or any ROS 2 namespace
        /// with --allow-everything.
        name: String,
        /// For a name that is not one of the graph's: grant every topic, service and action of the
        /// domain (sros2's default policy).
        #[arg(long)]
        allow_everything: bool,
        /// The DDS domain the permissions are for [default: ROS_DOMAIN_ID, else 0].
        #[arg(long)]
        domain: Option<u32>,
    },
    /// The graph's enclaves and what runs in each.
    ListEnclaves,
}

pub fn run(command: SecurityCommand) -> anyhow::Result<()> {
    match command {
        SecurityCommand::CreateKeystore { dir, enclaves, domain } => {
            let domain = domain_id(domain)?;
            create_keystore(&dir, domain)?;
            println!("keystore: {} (domain {domain})", dir.display());
            if enclaves {
                for (name, _) in ENCLAVES {
                    let grant = grant(name).expect("every listed enclave has a grant");
                    println!("enclave: {}", create_enclave(&dir, name, &grant, domain)?.display());
                }
            }
            Ok(())
        }
        SecurityCommand::CreateEnclave { dir, name, allow_everything, domain } => {
            let domain = domain_id(domain)?;
            let grant = match (grant(&name), allow_everything) {
                (Some(g), false) => g,
                (Some(_), true) => anyhow::bail!(
                    "{name} is one of the graph's enclaves: its permissions are its nodes' (drop --allow-everything)"
                ),
                (None, true) => Grant::everything(),
                (None, false) => anyhow::bail!(
                    "{name} is not one of the graph's enclaves ({}); for another process give --allow-everything",
                    ENCLAVES.map(|(n, _)| n).join(", ")
                ),
            };
            println!("enclave: {}", create_enclave(&dir, &name, &grant, domain)?.display());
            Ok(())
        }
        SecurityCommand::ListEnclaves => {
            for (name, what) in ENCLAVES {
                println!("{name:<26} {what}");
            }
            Ok(())
        }
    }
}

/// The domain given, else ROS_DOMAIN_ID's, else 0 (as sros2 takes it).
fn domain_id(given: Option<u32>) -> anyhow::Result<u32> {
    match (given, std::env::var("ROS_DOMAIN_ID")) {
        (Some(d), _) => Ok(d),
        (None, Ok(v)) if !v.trim().is_empty() => {
            v.trim().parse().map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID={v:?} is not a domain number"))
        }
        _ => Ok(0),
    }
}
