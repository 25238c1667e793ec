"""Certificates for a TLS deployment: one CA, and one key pair per identity.

An identity is ``<role>.<host>`` (``physics.sim``, ``autopilot.agents``) or ``operator.<host>``
for the tools an operator runs on a host (``up``'s own session, ``demo --attach``, ``status``).
The identity is the certificate's common name; the router's access control matches on it. Each
certificate also names its host's address (and loopback) as subject alternative names, so Zenoh
can verify the name of the host it connects to.

Layout written by :func:`generate` (``plumeswarm certs generate``)::

    DIR/ca.pem  DIR/ca.key              the CA (keep ca.key off the hosts)
    DIR/<host>/<identity>.pem|.key      one pair per identity, for that host only
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from swarmbus.errors import PlumeswarmError

OPERATOR = "operator"
CA_NAME = "plumeswarm deployment CA"


class CertError(PlumeswarmError, ValueError):
    """A certificate could not be written or read: one line saying which file and why."""


def identity(role: str, host: str) -> str:
    return f"{role}.{host}"


@dataclass(frozen=True)
class Issued:
    identity: str
    cert: Path
    key: Path


def _name(common_name: str) -> x509.Name:
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "plumeswarm"),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(pem)


def _write_cert(path: Path, cert: x509.Certificate) -> None:
    path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def _alt_names(addresses: Iterable[str]) -> list[x509.GeneralName]:
    names: list[x509.GeneralName] = []
    for a in dict.fromkeys([*addresses, "127.0.0.1", "localhost"]):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(a)))
        except ValueError:
            names.append(x509.DNSName(a))
    return names


class Authority:
    """A CA that issues identity certificates (server and client use: Zenoh links are both)."""

    def __init__(self, key: ec.EllipticCurvePrivateKey, cert: x509.Certificate) -> None:
        self.key, self.cert = key, cert

    @classmethod
    def create(cls, days: int, common_name: str = CA_NAME) -> Authority:
        key = _key()
        now = dt.datetime.now(dt.UTC)
        cert = (
            x509.CertificateBuilder()
            .subject_name(_name(common_name))
            .issuer_name(_name(common_name))
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(
                x509.KeyUsage(
                    digital_signature=True,
                    key_cert_sign=True,
                    crl_sign=True,
                    content_commitment=False,
                    key_encipherment=False,
                    data_encipherment=False,
                    key_agreement=False,
                    encipher_only=False,
                    decipher_only=False,
                ),
                critical=True,
            )
            .add_extension(
                x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False
            )
            .sign(key, hashes.SHA256())
        )
        return cls(key, cert)

    @classmethod
    def load(cls, directory: Path) -> Authority:
        """The CA that :func:`generate` wrote into ``directory`` (to issue more identities)."""
        key = serialization.load_pem_private_key((directory / "ca.key").read_bytes(), None)
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise CertError(f"{directory / 'ca.key'}: not an EC private key")
        return cls(key, x509.load_pem_x509_certificate((directory / "ca.pem").read_bytes()))

    def issue(
        self, common_name: str, addresses: Iterable[str], days: int
    ) -> tuple[ec.EllipticCurvePrivateKey, x509.Certificate]:
        key = _key()
        now = dt.datetime.now(dt.UTC)
        cert = (
            x509.CertificateBuilder()
            .subject_name(_name(common_name))
            .issuer_name(self.cert.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName(_alt_names(addresses)), critical=False)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
            .add_extension(
                x509.AuthorityKeyIdentifier.from_issuer_public_key(self.key.public_key()),
                critical=False,
            )
            .sign(self.key, hashes.SHA256())
        )
        return key, cert

    def save(self, out: Path) -> None:
        _write_cert(out / "ca.pem", self.cert)
        _write_key(out / "ca.key", self.key)

    def issue_to(self, out: Path, common_name: str, addresses: Iterable[str], days: int) -> Issued:
        out.mkdir(parents=True, exist_ok=True)
        key, cert = self.issue(common_name, addresses, days)
        issued = Issued(common_name, out / f"{common_name}.pem", out / f"{common_name}.key")
        _write_cert(issued.cert, cert)
        _write_key(issued.key, key)
        return issued


@dataclass(frozen=True)
class HostIdentities:
    host: str
    addresses: tuple[str, ...]
    identities: tuple[str, ...]


def generate(hosts: Iterable[HostIdentities], out: Path, days: int = 365) -> list[Issued]:
    """A fresh CA in ``out`` and one certificate per identity per host."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        if (out / "ca.pem").exists():
            raise CertError(f"{out / 'ca.pem'} exists: refusing to replace a deployment's CA")
        ca = Authority.create(days)
        ca.save(out)
        return [
            ca.issue_to(out / h.host, name, h.addresses, days)
            for h in hosts
            for name in h.identities
        ]
    except OSError as exc:
        raise CertError(f"cannot write certificates to {out}: {exc.strerror or exc}") from None


def common_name_of(path: Path) -> str:
    cert = x509.load_pem_x509_certificate(path.read_bytes())
    return str(cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value)
