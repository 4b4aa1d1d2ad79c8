//! `probebridge opcua-certificate [--renew]`: the OPC UA face's server certificate of
//! the gateway configuration (see `serve::opcua::certificate`): its names and validity,
//! or, with `--renew`, a new one in its place. `serve` refuses an expired certificate;
//! this is how it is renewed.

use crate::serve::config::GatewayConfig;
use std::path::Path;

pub fn run(config: &Path, renew: bool) -> Result<(), String> {
    let cfg = GatewayConfig::load(config).map_err(|e| e.to_string())?;
    let (machine, _) =
        crate::session::resolve_machine(&cfg.machine_options()).map_err(|e| e.to_string())?;
    let line = crate::serve::opcua::certificate_command(&cfg, &machine.name, renew)?;
    crate::say!("{line}");
    if renew {
        crate::say!(
            "restart the service to use it; clients trust it as they trusted the old one \
             (docs/opcua.md, \"The certificate\")"
        );
    }
    Ok(())
}
