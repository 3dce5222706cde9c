"""The certificates and the secret of the link between two hosts (`dume certs`).

When the robot's services and the station's (the semantic map) run on two hosts,
each host has its own router, and the two routers talk over one link: TLS with both
sides' certificates checked (mutual TLS), both signed by a certificate authority of the
deployment's own. On top of TLS the station's router logs in to the robot's (Zenoh's
user and password, `LINK_USER` and the link's secret): the robot's router refuses a
link without them, and its access list lets that link carry only what the station's
services and its users may (`common.access`), so a certificate alone opens nothing.

`make_certs` writes one folder:

- `ca.pem`: the authority's certificate (both hosts); `ca-key.pem`: its key, kept where
  the certificates are made, never copied to a host;
- `robot.pem`, `robot-key.pem` and `station.pem`, `station-key.pem`: each host's own
  (common name `robot` or `station`: the access lists name the link by it), valid for
  the names and addresses given (the robot's address is what the station checks);
- `link.secret`: the station's password on the robot's router (both hosts).

Keys are ECDSA P-256, certificates valid `days` (two years by default); every file
that is secret is written mode 0600 in a folder only its owner may enter.
"""

from __future__ import annotations

import datetime
import ipaddress
import secrets
from collections.abc import Sequence
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from common.runfiles import write_private, write_whole

#: The two hosts of a split stack; each certificate's common name is its host's.
HOSTS = ("robot", "station")
#: The name the station's router logs in with on the robot's router.
LINK_USER = "station"
CA = "ca.pem"
CA_KEY = "ca-key.pem"
SECRET = "link.secret"


#: What the authority's key may do: sign certificates (and their revocation lists).
CA_USAGE = x509.KeyUsage(
    digital_signature=True,
    content_commitment=False,
    key_encipherment=False,
    data_encipherment=False,
    key_agreement=False,
    key_cert_sign=True,
    crl_sign=True,
    encipher_only=False,
    decipher_only=False,
)


class CertsError(RuntimeError):
    """The link's certificates are missing, unreadable or not for this host."""


def cert_files(folder: Path, host: str) -> dict[str, Path]:
    """The files a host's router reads: the authority, its certificate and key, the
    link's secret; CertsError naming the first that is missing and how to make it."""
    files = {
        "ca": folder / CA,
        "cert": folder / f"{host}.pem",
        "key": folder / f"{host}-key.pem",
        "secret": folder / SECRET,
    }
    for path in files.values():
        if not path.is_file():
            raise CertsError(
                f"no {path.name} in {folder} for the {host}'s router: make the link's "
                f"certificates with `dume certs --out {folder}` and copy ca.pem, "
                f"{host}.pem, {host}-key.pem and link.secret to this host"
            )
    return files


def link_secret(folder: Path) -> str:
    """The station's password on the robot's router (`link.secret`)."""
    secret = (folder / SECRET).read_text().strip()
    if not secret:
        raise CertsError(f"{folder / SECRET} is empty: make the certificates again")
    return secret


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _alt_names(names: Sequence[str]) -> list[x509.GeneralName]:
    out: list[x509.GeneralName] = []
    for name in dict.fromkeys(names):
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            out.append(x509.DNSName(name))
    return out


def make_certs(
    folder: Path,
    robot_names: Sequence[str] = ("localhost", "127.0.0.1"),
    station_names: Sequence[str] = ("localhost", "127.0.0.1"),
    days: int = 730,
) -> dict[str, Path]:
    """Write the authority, both hosts' certificates and the link's secret into
    `folder` (module docstring); `*_names`: the DNS names and IP addresses each host's
    certificate is valid for (the robot's must hold the address the station connects
    to). Returns the files by name. Overwrites an earlier set: every host needs the new
    one."""
    folder.mkdir(parents=True, exist_ok=True)
    folder.chmod(0o700)
    now = datetime.datetime.now(datetime.UTC)
    until = now + datetime.timedelta(days=days)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = (
        x509.CertificateBuilder()
        .subject_name(_name("dume link authority"))
        .issuer_name(_name("dume link authority"))
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now)
        .not_valid_after(until)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(CA_USAGE, critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), False)
        .sign(ca_key, hashes.SHA256())
    )
    out = {CA: folder / CA, CA_KEY: folder / CA_KEY, SECRET: folder / SECRET}
    write_whole(out[CA], ca.public_bytes(serialization.Encoding.PEM))
    write_private(out[CA_KEY], _key_pem(ca_key))
    for host, names in zip(HOSTS, (robot_names, station_names), strict=True):
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (
            x509.CertificateBuilder()
            .subject_name(_name(host))
            .issuer_name(ca.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now)
            .not_valid_after(until)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName(_alt_names([host, *names])), False)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
            .add_extension(
                x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), False
            )
            .sign(ca_key, hashes.SHA256())
        )
        out[f"{host}.pem"] = folder / f"{host}.pem"
        out[f"{host}-key.pem"] = folder / f"{host}-key.pem"
        write_whole(out[f"{host}.pem"], cert.public_bytes(serialization.Encoding.PEM))
        write_private(out[f"{host}-key.pem"], _key_pem(key))
    write_private(out[SECRET], (secrets.token_urlsafe(32) + "\n").encode())
    return out


def common_name(cert_pem: bytes) -> str:
    """A certificate's common name (what the routers' access lists call the link)."""
    cert = x509.load_pem_x509_certificate(cert_pem)
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)
