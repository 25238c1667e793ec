"""``plumeswarm certs generate|show``: the certificates of a TLS deployment (hosts file)."""

from __future__ import annotations

from pathlib import Path

import click

from plumeswarm.cli.common import out_dir_option

# cryptography and the launcher load only when a certs command runs, not with every command.


@click.group()
def certs() -> None:
    """Certificates for Zenoh over mutual TLS across hosts."""


@certs.command("generate")
@click.option(
    "--hosts",
    "hosts_file",
    required=True,
    type=click.Path(path_type=Path),
    help="Hosts file of the deployment: its hosts and roles get one certificate each.",
)
@out_dir_option("Directory (default: the hosts file's [tls] certs).")
@click.option(
    "--days",
    type=click.IntRange(1, 3650),
    default=365,
    show_default=True,
    help="Days the CA and the certificates are valid.",
)
def certs_generate(hosts_file: Path, out: Path | None, days: int) -> None:
    """A CA and one certificate per role and host (common name <role>.<host>)."""
    from deploy.certs import CertError, generate
    from deploy.hosts import HostsError, load_deployment
    from deploy.security import host_identities
    from plumeswarm.cli.common import fail

    try:
        dep = load_deployment(hosts_file)
    except HostsError as exc:
        fail(str(exc))
    if out is None:
        if dep.tls is None:
            fail(f"{hosts_file} has no [tls] section: give --out DIR")
        out = Path(dep.tls.certs)
    try:
        issued = generate(host_identities(dep), out, days)
    except CertError as exc:
        fail(str(exc))
    click.echo(f"{out}/ca.pem: the CA (keep {out}/ca.key off the hosts)")
    for i in issued:
        click.echo(f"{i.cert}: {i.identity}")
    click.echo(f"copy {out}/ca.pem and {out}/<host>/ to each host, at the same path")


@certs.command("show")
@click.argument("files", nargs=-1, type=click.Path(dir_okay=False, path_type=Path))
def certs_show(files: tuple[Path, ...]) -> None:
    """The identity (common name) of each certificate FILE."""
    from deploy.certs import common_name_of
    from plumeswarm.cli.common import fail

    for f in files:
        try:
            click.echo(f"{f}: {common_name_of(f)}")
        except (OSError, ValueError, IndexError) as exc:
            fail(f"{f}: not a readable PEM certificate ({exc})")
