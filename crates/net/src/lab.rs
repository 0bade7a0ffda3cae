//! A lab: hubs and clients on several machines that trust one another, and no one else, made
//! by two commands (`envhub lab init`, `envhub lab add`).
//!
//! The lab is a certificate authority of its own (an ECDSA P-256 key in a folder only its user
//! can enter) and one Zenoh config per member: the member's certificate and key, signed by the
//! lab's CA, and the CA, inline (`*_base64`), with TLS client certificates on (`enable_mtls`).
//! Members open and accept `tls/` links only (`transport/link/protocols`). Every link between
//! members is then checked at both ends by the one CA, so a hub may listen
//! beyond loopback, scout and connect out (see [`crate::exposure`]), a client scouts and follows
//! gossip, and a peer without a certificate of this lab gets no link at all. Addresses are not
//! checked on connect (`verify_name_on_connect: false`): the lab's CA is the trust, whatever
//! address a member is reached at (multicast finds members by address). Hub names are checked
//! instead, where it matters: every config lists the lab's members (as they were when it was
//! written) in Zenoh's access control, so a hub's name (`envhub/hub/NAME/**`: its tokens,
//! queryables and answers) comes in only on a link whose certificate is member `NAME`'s, and
//! no member can pose as another member's hub, at first contact either. Session keys still
//! come from the key exchange with each hub's pinned identity ([`crate::identity`]); TLS adds
//! that nothing of a link is readable.
//!
//! A member's config holds its private key: it is written 0600 and copied to that machine only.
//!
//! Zenoh's TLS links check no revocation list, so a member is removed (`envhub lab remove`) by
//! a new CA: the lab's key and certificate are made anew, every other member's certificate is
//! signed again by it (same key, same names) and its config rewritten, and the removed
//! member's config is deleted. Each remaining member picks the change up from one file, its
//! new config; the removed member's copy trusts and carries only the old CA, so no member
//! with a new config links to it, nor it to them.

use base64::Engine;
use envhub_core::private_dir;
use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};
use std::path::{Path, PathBuf};

/// The lab's CA certificate, in the lab's folder.
pub const CA_CERT: &str = "ca.pem";
/// The lab's CA key (0600), in the lab's folder: whoever holds it can add members.
pub const CA_KEY: &str = "ca.key";
/// The port a router's config listens on.
pub const ROUTER_PORT: u16 = 7447;
/// How long certificates are valid, in years.
const YEARS: u64 = 5;

/// What a member's config makes of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// A hub or a client (`mode: peer`): `envhub --zenoh-config NAME.json5 serve|hubs|run ...`.
    Member,
    /// A client that reaches the lab through one router (`mode: client`: every message goes
    /// through it; a `peer` client's interests do not cross a router in Zenoh 1.10, so it sees
    /// no hub there): `envhub --zenoh-config NAME.json5 --connect tls/ROUTER:7447 hubs`.
    RouterClient,
    /// A Zenoh router that members reach one another through (`mode: router`, listening on
    /// `tls/[::]:7447`): `zenohd -c NAME.json5`, or `envhub lab router NAME.json5`.
    Router,
}

/// A member's or a lab's name: 1 to 64 of `A-Z a-z 0-9 . _ -`, not starting with `.` or `-`
/// (it names a file and a certificate).
pub fn check_name(what: &str, name: &str) -> Result<(), String> {
    let ok = (1..=64).contains(&name.len())
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
        && !name.starts_with(['.', '-']);
    if ok {
        Ok(())
    } else {
        Err(format!(
            "`{name}` is not a valid {what} name\nhint: 1 to 64 letters, digits, `.`, `_` or `-`, \
             not starting with `.` or `-`"
        ))
    }
}

/// Makes lab `name` in folder `dir` (made 0700 where missing, every component checked): its
/// CA certificate and key. A folder that already holds a CA is refused, never overwritten.
pub fn init(dir: &Path, name: &str) -> Result<(), String> {
    check_name("lab", name)?;
    private_dir::ensure(dir).map_err(|e| format!("cannot use `{}`: {e}", dir.display()))?;
    let key_path = dir.join(CA_KEY);
    if key_path.symlink_metadata().is_ok() {
        return Err(format!(
            "`{}` already holds a lab (its `{CA_KEY}`)\nhint: add members with `envhub lab add \
             {} NAME`, or choose another folder for a new lab",
            dir.display(),
            dir.display()
        ));
    }
    let key = KeyPair::generate().map_err(|e| format!("cannot make the lab's key: {e}"))?;
    let cert = ca_params(name)
        .self_signed(&key)
        .map_err(|e| format!("cannot make the lab's certificate: {e}"))?;
    // The key first and without replacing: of two `init`s at once, one wins whole.
    if !write(&key_path, key.serialize_pem().as_bytes(), false)? {
        return Err(format!(
            "`{}` was made by another process meanwhile",
            key_path.display()
        ));
    }
    write(&dir.join(CA_CERT), cert.pem().as_bytes(), true)?;
    Ok(())
}

/// Adds member `member` to the lab in `dir`: writes `DIR/MEMBER.json5` (0600), its Zenoh config
/// with a certificate of the lab's CA. An existing config of that name is refused. The other
/// members' configs are written again (same certificate and key) to check the new member's
/// name too ([`member_config`]); its path first, then theirs, in name order.
pub fn add(dir: &Path, member: &str, role: Role) -> Result<Vec<PathBuf>, String> {
    check_name("member", member)?;
    private_dir::check(dir).map_err(|e| format!("cannot use `{}`: {e}", dir.display()))?;
    let read = |file: &str| -> Result<String, String> {
        let path = dir.join(file);
        match private_dir::read_file(&path, 64 * 1024) {
            Ok(Some(body)) => String::from_utf8(body)
                .map_err(|_| format!("`{}` is not a PEM file", path.display())),
            Ok(None) => Err(format!(
                "`{}` holds no lab (no `{file}`)\nhint: make one with `envhub lab init {}`",
                dir.display(),
                dir.display()
            )),
            Err(e) => Err(format!("cannot read `{}`: {e}", path.display())),
        }
    };
    let ca_key = KeyPair::from_pem(&read(CA_KEY)?)
        .map_err(|e| format!("`{}` is not a key: {e}", dir.join(CA_KEY).display()))?;
    let ca_pem = read(CA_CERT)?;
    let issuer = Issuer::from_ca_cert_pem(&ca_pem, &ca_key).map_err(|e| {
        format!(
            "`{}` is not a certificate: {e}",
            dir.join(CA_CERT).display()
        )
    })?;
    let mut others = Vec::new();
    for other in members(dir)?.into_iter().filter(|m| m != member) {
        others.push(read_member(&dir.join(format!("{other}.json5")), &other)?);
    }
    let key = KeyPair::generate().map_err(|e| format!("cannot make {member}'s key: {e}"))?;
    let cert = member_params(member)?
        .signed_by(&key, &issuer)
        .map_err(|e| format!("cannot sign {member}'s certificate: {e}"))?;
    let new = Member {
        name: member.to_string(),
        role,
        cert: cert.pem(),
        key: key.serialize_pem(),
    };
    let roster: Vec<(String, Role)> = others
        .iter()
        .chain([&new])
        .map(|m| (m.name.clone(), m.role))
        .collect();
    let path = dir.join(format!("{member}.json5"));
    if !write(
        &path,
        member_config(&new, &ca_pem, &roster).as_bytes(),
        false,
    )? {
        return Err(format!(
            "`{}` already exists\nhint: a member keeps its config; to shut the old one out and \
             make a new one, `envhub lab remove {} {member}`, then add it again",
            path.display(),
            dir.display()
        ));
    }
    let mut written = vec![path];
    for other in &others {
        let path = dir.join(format!("{}.json5", other.name));
        write(
            &path,
            member_config(other, &ca_pem, &roster).as_bytes(),
            true,
        )?;
        written.push(path);
    }
    Ok(written)
}

/// The lab's members in `dir`: the names of its `NAME.json5` configs, sorted.
pub fn members(dir: &Path) -> Result<Vec<String>, String> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| format!("cannot read `{}`: {e}", dir.display()))?;
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter_map(|f| f.strip_suffix(".json5").map(str::to_string))
        .filter(|n| check_name("member", n).is_ok())
        .collect();
    names.sort();
    Ok(names)
}

/// Removes member `member` from the lab in `dir`: makes the lab's CA anew, signs every other
/// member's certificate again with it (its key and names kept) and rewrites its config, then
/// deletes `member`'s config. The remaining members' configs, rewritten, in name order.
///
/// The CA is written first and the removed member's config deleted last: a run cut short is
/// completed by running it again.
pub fn remove(dir: &Path, member: &str) -> Result<Vec<PathBuf>, String> {
    private_dir::check(dir).map_err(|e| format!("cannot use `{}`: {e}", dir.display()))?;
    let all = members(dir)?;
    if !all.iter().any(|m| m == member) {
        let known = if all.is_empty() {
            "it has no members yet".to_string()
        } else {
            format!("its members are {}", all.join(", "))
        };
        return Err(format!(
            "`{member}` is not a member of the lab in `{}` (no `{member}.json5` there)\nhint: \
             {known}",
            dir.display()
        ));
    }
    let ca_pem = read_text(dir, CA_CERT)?;
    let lab = common_name(&ca_pem).map_err(|e| format!("`{}` {e}", dir.join(CA_CERT).display()))?;
    let lab = lab.strip_prefix("envhub lab ").unwrap_or(&lab).to_string();
    let ca_key = KeyPair::generate().map_err(|e| format!("cannot make the lab's key: {e}"))?;
    let ca_cert = ca_params(&lab)
        .self_signed(&ca_key)
        .map_err(|e| format!("cannot make the lab's certificate: {e}"))?;
    let issuer = Issuer::from_ca_cert_pem(&ca_cert.pem(), &ca_key)
        .map_err(|e| format!("cannot use the lab's new certificate: {e}"))?;
    // Every config made before anything is written: a member that cannot be read stops the
    // removal with the lab as it was.
    let mut kept = Vec::new();
    for other in all.iter().filter(|m| *m != member) {
        kept.push(reissue(
            &dir.join(format!("{other}.json5")),
            other,
            &issuer,
        )?);
    }
    let roster: Vec<(String, Role)> = kept.iter().map(|m| (m.name.clone(), m.role)).collect();
    let rewritten: Vec<(PathBuf, String)> = kept
        .iter()
        .map(|m| {
            let path = dir.join(format!("{}.json5", m.name));
            (path, member_config(m, &ca_cert.pem(), &roster))
        })
        .collect();
    write(&dir.join(CA_KEY), ca_key.serialize_pem().as_bytes(), true)?;
    write(&dir.join(CA_CERT), ca_cert.pem().as_bytes(), true)?;
    for (path, config) in &rewritten {
        write(path, config.as_bytes(), true)?;
    }
    let gone = dir.join(format!("{member}.json5"));
    std::fs::remove_file(&gone).map_err(|e| format!("cannot remove `{}`: {e}", gone.display()))?;
    Ok(rewritten.into_iter().map(|(path, _)| path).collect())
}

/// `file` of the lab in `dir`, as text.
fn read_text(dir: &Path, file: &str) -> Result<String, String> {
    let path = dir.join(file);
    match private_dir::read_file(&path, 1 << 20) {
        Ok(Some(body)) => {
            String::from_utf8(body).map_err(|_| format!("`{}` is not text", path.display()))
        }
        Ok(None) => Err(format!(
            "`{}` holds no lab (no `{file}`)\nhint: make one with `envhub lab init {}`",
            dir.display(),
            dir.display()
        )),
        Err(e) => Err(format!("cannot read `{}`: {e}", path.display())),
    }
}

/// The DER of a PEM certificate.
fn der_of(pem: &str) -> Result<Vec<u8>, String> {
    let body: String = pem
        .lines()
        .filter(|l| !l.starts_with("-----"))
        .collect::<Vec<_>>()
        .concat();
    base64::engine::general_purpose::STANDARD
        .decode(body.trim())
        .map_err(|e| format!("is not a PEM certificate: {e}"))
}

/// A certificate's subject common name.
fn common_name(pem: &str) -> Result<String, String> {
    let der = der_of(pem)?;
    let (_, cert) = x509_parser::parse_x509_certificate(&der)
        .map_err(|e| format!("is not a certificate: {e}"))?;
    cert.subject()
        .iter_common_name()
        .next()
        .and_then(|cn| cn.as_str().ok())
        .map(str::to_string)
        .ok_or_else(|| "has no common name".to_string())
}

/// A certificate's subject alternative names (DNS names and IP addresses), as text.
fn alt_names(pem: &str) -> Result<Vec<String>, String> {
    use x509_parser::extensions::GeneralName;
    let der = der_of(pem)?;
    let (_, cert) = x509_parser::parse_x509_certificate(&der)
        .map_err(|e| format!("is not a certificate: {e}"))?;
    let Ok(Some(san)) = cert.subject_alternative_name() else {
        return Ok(Vec::new());
    };
    Ok(san
        .value
        .general_names
        .iter()
        .filter_map(|n| match n {
            GeneralName::DNSName(d) => Some(d.to_string()),
            GeneralName::IPAddress(ip) => match ip.len() {
                4 => Some(std::net::Ipv4Addr::from(<[u8; 4]>::try_from(*ip).ok()?).to_string()),
                16 => Some(std::net::Ipv6Addr::from(<[u8; 16]>::try_from(*ip).ok()?).to_string()),
                _ => None,
            },
            _ => None,
        })
        .collect())
}

/// A member as its config holds it.
struct Member {
    name: String,
    role: Role,
    /// Its certificate and key (PEM).
    cert: String,
    key: String,
}

/// `member`'s config at `path`, read back: its role, certificate and key.
fn read_member(path: &Path, member: &str) -> Result<Member, String> {
    let shown = path.display();
    let text = match private_dir::read_file(path, 1 << 20) {
        Ok(Some(body)) => String::from_utf8(body).map_err(|_| format!("`{shown}` is not text"))?,
        Ok(None) => return Err(format!("`{shown}` went away meanwhile")),
        Err(e) => return Err(format!("cannot read `{shown}`: {e}")),
    };
    let config = zenoh::Config::from_json5(&text)
        .map_err(|e| format!("`{shown}` is not a Zenoh config: {e}"))?;
    let field = |key: &str| -> Result<String, String> {
        let json = config
            .get_json(key)
            .map_err(|e| format!("`{shown}` has no `{key}`: {e}"))?;
        let b64: String = serde_json::from_str(&json)
            .map_err(|_| format!("`{shown}`: `{key}` is not a string"))?;
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .map_err(|e| format!("`{shown}`: `{key}` is not base64: {e}"))?;
        String::from_utf8(bytes).map_err(|_| format!("`{shown}`: `{key}` is not PEM"))
    };
    let role = match config.get_json("mode").unwrap_or_default().as_str() {
        "\"client\"" => Role::RouterClient,
        "\"router\"" => Role::Router,
        _ => Role::Member,
    };
    Ok(Member {
        name: member.to_string(),
        role,
        cert: field("transport/link/tls/listen_certificate_base64")?,
        key: field("transport/link/tls/listen_private_key_base64")?,
    })
}

/// `member`'s config at `path`, read back with its certificate signed again by `issuer`: its
/// role, key and names kept.
fn reissue(path: &Path, member: &str, issuer: &Issuer<'_, &KeyPair>) -> Result<Member, String> {
    let shown = path.display();
    let mut read = read_member(path, member)?;
    let key = KeyPair::from_pem(&read.key)
        .map_err(|e| format!("`{shown}`: its key is not a key: {e}"))?;
    let mut names = alt_names(&read.cert).map_err(|e| format!("`{shown}`: its certificate {e}"))?;
    if names.is_empty() {
        names.push(member.to_string());
    }
    read.cert = member_params_named(member, names)?
        .signed_by(&key, issuer)
        .map_err(|e| format!("cannot sign {member}'s certificate: {e}"))?
        .pem();
    Ok(read)
}

fn write(path: &Path, body: &[u8], replace: bool) -> Result<bool, String> {
    private_dir::write_file(path, body, 0o600, replace)
        .map_err(|e| format!("cannot write `{}`: {e}", path.display()))
}

/// The validity of certificates made now: from a day ago (clocks differ) for [`YEARS`] years.
fn validity(params: &mut CertificateParams) {
    const DAY: u64 = 86_400;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let from = rcgen::date_time_ymd(1970, 1, 1) + now - std::time::Duration::from_secs(DAY);
    params.not_before = from;
    params.not_after = from + std::time::Duration::from_secs(YEARS * 365 * DAY);
}

fn ca_params(lab: &str) -> CertificateParams {
    let mut params = CertificateParams::default();
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, format!("envhub lab {lab}"));
    params.distinguished_name = dn;
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    validity(&mut params);
    params
}

fn member_params(member: &str) -> Result<CertificateParams, String> {
    member_params_named(member, vec![member.to_string()])
}

/// A member's certificate, for its subject alternative `names` (DNS names and addresses).
fn member_params_named(member: &str, names: Vec<String>) -> Result<CertificateParams, String> {
    let mut params = CertificateParams::new(names)
        .map_err(|e| format!("`{member}` cannot name a certificate: {e}"))?;
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, member);
    params.distinguished_name = dn;
    params.is_ca = IsCa::ExplicitNoCa;
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    // Every member both accepts links (a hub, a router) and opens them (all of them).
    params.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    validity(&mut params);
    Ok(params)
}

/// The access control that checks hub names against certificates: a member's config lets a
/// hub's name (`envhub/hub/NAME/**`: its tokens, queryables and answers) in only from a link
/// whose certificate is the member `NAME`'s, for every member of `roster` but routers (which
/// pass on what their own links let in, checked by the same rules in their config). `None`
/// where no member's name needs guarding.
fn names_checked(roster: &[(String, Role)]) -> Option<serde_json::Value> {
    let linked: Vec<&str> = roster
        .iter()
        .filter(|(_, role)| *role != Role::Router)
        .map(|(name, _)| name.as_str())
        .collect();
    let (mut rules, mut subjects, mut policies) = (Vec::new(), Vec::new(), Vec::new());
    for (k, name) in linked.iter().enumerate() {
        let others: Vec<&str> = linked.iter().copied().filter(|n| n != name).collect();
        if others.is_empty() {
            continue;
        }
        rules.push(serde_json::json!({
            "id": format!("hub-{k}"),
            "permission": "deny",
            "flows": ["ingress"],
            // Not puts: clients put a hub's echo requests on its keys (`envhub bench`).
            "messages": ["liveliness_token", "declare_queryable", "reply"],
            "key_exprs": [format!("envhub/hub/{name}"), format!("envhub/hub/{name}/**")],
        }));
        subjects.push(serde_json::json!({ "id": format!("not-{k}"), "cert_common_names": others }));
        policies.push(serde_json::json!({
            "id": format!("name-{k}"),
            "rules": [format!("hub-{k}")],
            "subjects": [format!("not-{k}")],
        }));
    }
    (!rules.is_empty()).then(|| {
        serde_json::json!({
            "enabled": true,
            "default_permission": "allow",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        })
    })
}

/// The Zenoh config (JSON5) of `member`: TLS with client certificates of the lab on every link,
/// and hub names checked against the certificates of the members of `roster`.
fn member_config(member: &Member, ca: &str, roster: &[(String, Role)]) -> String {
    let (role, cert, key) = (member.role, member.cert.as_str(), member.key.as_str());
    let member = member.name.as_str();
    let b64 = |pem: &str| base64::engine::general_purpose::STANDARD.encode(pem.as_bytes());
    let mut tls = serde_json::Map::new();
    for (k, v) in [
        ("root_ca_certificate_base64", b64(ca)),
        ("listen_certificate_base64", b64(cert)),
        ("listen_private_key_base64", b64(key)),
        ("connect_certificate_base64", b64(cert)),
        ("connect_private_key_base64", b64(key)),
    ] {
        tls.insert(k.into(), v.into());
    }
    tls.insert("enable_mtls".into(), true.into());
    tls.insert("verify_name_on_connect".into(), false.into());
    let mut config = serde_json::json!({
        "mode": match role {
            Role::Member => "peer",
            Role::RouterClient => "client",
            Role::Router => "router",
        },
        // TLS only: no link of a member is ever unchecked (and a client scouts by default).
        "transport": { "link": { "protocols": ["tls"], "tls": tls } },
    });
    if role == Role::Router {
        config["listen"] = serde_json::json!({ "endpoints": [format!("tls/[::]:{ROUTER_PORT}")] });
    }
    if let Some(acl) = names_checked(roster) {
        config["access_control"] = acl;
    }
    let how = match role {
        Role::Member => {
            "a hub (`envhub --zenoh-config FILE serve --listen tls/0.0.0.0:7447`) or a client \
             (`envhub --zenoh-config FILE hubs`)"
        }
        Role::RouterClient => {
            "a client through a router (`envhub --zenoh-config FILE --connect tls/ROUTER:7447 \
             hubs`)"
        }
        Role::Router => "a Zenoh router (`zenohd -c FILE`, or `envhub lab router FILE`)",
    };
    format!(
        "// envhub lab member `{member}`: {how}.\n// It holds {member}'s private key: copy it to \
         that machine only, mode 0600.\n{}\n",
        serde_json::to_string_pretty(&config).expect("JSON serializes")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn fresh(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("envhub-lab-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_lab_makes_private_configs_zenoh_reads_and_refuses_to_overwrite() {
        let dir = fresh("make");
        init(&dir, "test").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&dir), 0o700);
        assert_eq!(mode(&dir.join(CA_KEY)), 0o600);
        let e = init(&dir, "test").unwrap_err();
        assert!(e.contains("already holds a lab"), "{e}");
        for (name, role, mode_json) in [
            ("box1", Role::Member, "\"peer\""),
            ("far", Role::RouterClient, "\"client\""),
            ("hop", Role::Router, "\"router\""),
        ] {
            let path = add(&dir, name, role).unwrap().remove(0);
            assert_eq!(mode(&path), 0o600);
            let config = zenoh::Config::from_file(&path).unwrap();
            assert_eq!(config.get_json("mode").unwrap(), mode_json);
            assert_eq!(
                config.get_json("transport/link/tls/enable_mtls").unwrap(),
                "true"
            );
            let e = add(&dir, name, role).unwrap_err();
            assert!(e.contains("already exists"), "{e}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `members.json5`'s field `key` (a string).
    fn field(path: &Path, key: &str) -> String {
        zenoh::Config::from_file(path)
            .unwrap()
            .get_json(key)
            .unwrap()
    }

    /// Removing a member makes the CA anew and signs the others again with their keys, roles
    /// and names; the removed member's config is gone; an unknown member is named with the
    /// members there are.
    #[test]
    fn a_removed_member_leaves_the_others_on_a_new_ca() {
        let dir = fresh("remove");
        init(&dir, "test").unwrap();
        for (name, role) in [
            ("box1", Role::Member),
            ("gone", Role::Member),
            ("hop", Role::Router),
        ] {
            add(&dir, name, role).unwrap();
        }
        const CA: &str = "transport/link/tls/root_ca_certificate_base64";
        const KEY: &str = "transport/link/tls/listen_private_key_base64";
        const CERT: &str = "transport/link/tls/listen_certificate_base64";
        let box1 = dir.join("box1.json5");
        let (old_ca, old_key, old_cert) = (field(&box1, CA), field(&box1, KEY), field(&box1, CERT));
        let e = remove(&dir, "nobody").unwrap_err();
        assert!(
            e.contains("`nobody` is not a member") && e.contains("box1, gone, hop"),
            "{e}"
        );
        let rewritten = remove(&dir, "gone").unwrap();
        assert_eq!(rewritten, [box1.clone(), dir.join("hop.json5")]);
        assert!(!dir.join("gone.json5").exists());
        assert_eq!(members(&dir).unwrap(), ["box1", "hop"]);
        let new_ca = field(&box1, CA);
        assert_ne!(new_ca, old_ca, "the CA is new");
        let ca_pem = std::fs::read_to_string(dir.join(CA_CERT)).unwrap();
        let b64 = |pem: &str| {
            format!(
                "\"{}\"",
                base64::engine::general_purpose::STANDARD.encode(pem)
            )
        };
        assert_eq!(new_ca, b64(&ca_pem), "configs carry the CA of the folder");
        assert_eq!(field(&dir.join("hop.json5"), CA), new_ca);
        assert_eq!(field(&box1, KEY), old_key, "a member keeps its key");
        assert_ne!(
            field(&box1, CERT),
            old_cert,
            "its certificate is signed again"
        );
        assert_eq!(field(&dir.join("hop.json5"), "mode"), "\"router\"");
        let cert: String = serde_json::from_str(&field(&box1, CERT)).unwrap();
        let cert = String::from_utf8(
            base64::engine::general_purpose::STANDARD
                .decode(cert)
                .unwrap(),
        )
        .unwrap();
        assert_eq!(alt_names(&cert).unwrap(), ["box1"]);
        assert_eq!(common_name(&ca_pem).unwrap(), "envhub lab test");
        assert_eq!(mode(&box1), 0o600);
        // The CA's key is the new one: a member added now is of the new CA.
        let later = add(&dir, "later", Role::Member).unwrap().remove(0);
        assert_eq!(field(&later, CA), new_ca);
        let e = remove(&dir, "gone").unwrap_err();
        assert!(e.contains("box1, hop, later"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Every config lists the lab's members, so a hub's name comes in only from its member's
    /// certificate: adding a member writes the others again with it; routers are trusted to
    /// pass names on (their own config checks them), and Zenoh reads the rules.
    #[test]
    fn every_config_checks_hub_names_against_the_members_certificates() {
        let dir = fresh("names");
        init(&dir, "test").unwrap();
        let written = add(&dir, "a", Role::Member).unwrap();
        assert_eq!(written, [dir.join("a.json5")]);
        let acl = |m: &str| {
            zenoh::Config::from_file(dir.join(format!("{m}.json5")))
                .unwrap()
                .get_json("access_control")
                .ok()
                .and_then(|j| serde_json::from_str::<serde_json::Value>(&j).ok())
                .filter(|v| v["enabled"] == true)
        };
        assert!(acl("a").is_none(), "a member alone has no name to guard");
        add(&dir, "hop", Role::Router).unwrap();
        let written = add(&dir, "b", Role::Member).unwrap();
        let names: Vec<&str> = ["b", "a", "hop"].to_vec();
        assert_eq!(
            written,
            names
                .iter()
                .map(|m| dir.join(format!("{m}.json5")))
                .collect::<Vec<_>>(),
            "the new member's config, then the others' written again"
        );
        for member in ["a", "b", "hop"] {
            let acl = acl(member).unwrap_or_else(|| panic!("{member} checks names"));
            let messages = &acl["rules"][0]["messages"];
            assert_eq!(
                messages,
                &serde_json::json!(["liveliness_token", "declare_queryable", "reply"]),
                "a hub's tokens, queryables and answers; not clients' echo puts"
            );
            assert_eq!(acl["default_permission"], "allow");
            let subjects = acl["subjects"].as_array().unwrap();
            let rules = acl["rules"].as_array().unwrap();
            assert_eq!(
                rules.len(),
                2,
                "{member}: one rule per member but the router"
            );
            for (rule, subject) in rules.iter().zip(subjects) {
                let guarded = rule["key_exprs"][0].as_str().unwrap();
                let others = &subject["cert_common_names"];
                assert_eq!(rule["permission"], "deny");
                match guarded {
                    "envhub/hub/a" => assert_eq!(others, &serde_json::json!(["b"])),
                    "envhub/hub/b" => assert_eq!(others, &serde_json::json!(["a"])),
                    other => panic!("{member} guards {other}"),
                }
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).unwrap().permissions().mode() & 0o777
    }

    #[test]
    fn bad_names_and_a_folder_without_a_lab_are_named() {
        let dir = fresh("bad");
        for name in ["", "../x", "-x", "a b", &"x".repeat(65)] {
            let e = init(&dir, name).unwrap_err();
            assert!(e.contains("not a valid lab name"), "{name:?}: {e}");
        }
        private_dir::ensure(&dir).unwrap();
        let e = add(&dir, "box1", Role::Member).unwrap_err();
        assert!(
            e.contains("holds no lab") && e.contains("envhub lab init"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
