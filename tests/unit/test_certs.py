"""The link between two hosts: its certificates (`common.certs`), what each router lets
it carry (`common.access`), the routers' settings for it, which services each host
starts."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.exceptions import InvalidSignature

from common.access import (
    LINK_USER,
    SERVICES,
    access_control,
    link_settings,
    read_credentials,
    services_on,
)
from common.certs import CertsError, cert_files, common_name, make_certs
from common.config import Config, ConfigError, load_config
from deploy.stack import stack_env


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_the_certificates_are_signed_by_the_links_own_authority_and_keys_are_private(
    tmp_path: Path,
) -> None:
    made = make_certs(tmp_path / "certs", ["10.0.0.5", "b1.local"])
    ca = x509.load_pem_x509_certificate(made["ca.pem"].read_bytes())
    for host in ("robot", "station"):
        pem = made[f"{host}.pem"].read_bytes()
        assert common_name(pem) == host
        x509.load_pem_x509_certificate(pem).verify_directly_issued_by(ca)
        assert _mode(made[f"{host}-key.pem"]) == 0o600
    assert _mode(made["ca-key.pem"]) == 0o600 and _mode(made["link.secret"]) == 0o600
    assert _mode(tmp_path / "certs") == 0o700
    robot = x509.load_pem_x509_certificate(made["robot.pem"].read_bytes())
    names = robot.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "b1.local" in names.get_values_for_type(x509.DNSName)
    assert [str(a) for a in names.get_values_for_type(x509.IPAddress)] == ["10.0.0.5"]
    # a second set is another authority: the first set's hosts do not trust it
    again = make_certs(tmp_path / "other")
    other = x509.load_pem_x509_certificate(again["robot.pem"].read_bytes())
    with pytest.raises(InvalidSignature):
        other.verify_directly_issued_by(ca)


def test_a_host_without_its_files_is_told_what_to_copy(tmp_path: Path) -> None:
    make_certs(tmp_path)
    (tmp_path / "station-key.pem").unlink()
    assert cert_files(tmp_path, "robot")["cert"].name == "robot.pem"
    with pytest.raises(CertsError, match=r"no station-key\.pem .*dume certs"):
        cert_files(tmp_path, "station")


def _config(side: str, certs: Path, **more: object) -> Config:
    return load_config({"zenoh.side": side, "zenoh.certs": str(certs), **more})


def test_the_robots_router_lets_the_link_carry_the_stations_services_and_users_only(
    tmp_path: Path,
) -> None:
    acl = access_control(load_config({"zenoh.side": "robot"}))
    (subject,) = [s for s in acl["subjects"] if s["id"] == "link-station"]
    # both: the certificate's name and the login with the link's secret
    assert subject == {"id": "link-station", "cert_common_names": ["station"],
                       "usernames": [LINK_USER]}  # fmt: skip
    (policy,) = [p for p in acl["policies"] if p["id"] == "link-station"]
    owners = {r.split("-")[0] for r in policy["rules"]}
    assert owners == {"b1.semantic_map", "user"}
    rules = {r["id"]: r for r in acl["rules"]}
    carried = {k for r in policy["rules"] for k in rules[r]["key_exprs"]}
    for never in ("dume/b1/wbc/cmd_vel", "dume/b1/wbc/mode", "dume/b1/command",
                  "dume/b1/state_truth", "dume/world/push"):  # fmt: skip
        assert never not in carried
    station = access_control(load_config({"zenoh.side": "station"}))
    (subject,) = [s for s in station["subjects"] if s["id"] == "link-robot"]
    assert subject == {"id": "link-robot", "cert_common_names": ["robot"]}
    (policy,) = [p for p in station["policies"] if p["id"] == "link-robot"]
    robot = {f"b1.{name}" for name in services_on("robot")}
    assert {r.split("-")[0] for r in policy["rules"]} == {*robot, "user"}
    one_host = access_control(load_config({}))
    assert not [s for s in one_host["subjects"] if s["id"].startswith("link-")]


def test_each_router_gets_its_end_of_the_link(tmp_path: Path) -> None:
    certs = tmp_path / "certs"
    make_certs(certs)
    users = tmp_path / "users"
    users.write_text("mission:pw1\nuser:pw2\n")
    robot = link_settings(_config("robot", certs, **{"zenoh.link_port": 7500}), users)
    assert robot["listen/endpoints"] == ["tcp/127.0.0.1:7447", "tls/127.0.0.1:7500"]
    tls = robot["transport/link/tls"]
    assert tls["enable_mtls"] and tls["listen_certificate"].endswith("robot.pem")
    dictionary = Path(robot["transport/auth/usrpwd/dictionary_file"])
    secret = (certs / "link.secret").read_text().strip()
    assert read_credentials(dictionary) == {"mission": "pw1", "user": "pw2", LINK_USER: secret}
    assert _mode(dictionary) == 0o600
    station = link_settings(_config("station", certs), users)
    assert station["connect/endpoints"] == ["tls/127.0.0.1:7448"]
    assert station["transport/auth/usrpwd/password"] == secret
    assert station["transport/link/tls"]["connect_certificate"].endswith("station.pem")
    assert link_settings(load_config({}), users) == {}


def test_a_split_stack_refuses_settings_that_cannot_link() -> None:
    with pytest.raises(ConfigError, match="access_control"):
        load_config({"zenoh.side": "station", "zenoh.access_control": False})
    with pytest.raises(ConfigError, match="link_port"):
        load_config({"zenoh.side": "robot", "zenoh.port": 7448})
    with pytest.raises(ConfigError):
        load_config({"zenoh.side": "moon"})


def test_supervisord_starts_this_hosts_services_only(tmp_path: Path) -> None:
    def started(side: str) -> set[str]:
        env = stack_env(port=7447, run_id="r", run_dir=tmp_path, base={}, side=side)
        return {s for s in SERVICES if env[f"DUME_START_{s.upper()}"] == "true"}

    assert started("all") == set(SERVICES)
    assert started("robot") == set(SERVICES) - {"semantic_map"}
    assert started("station") == {"semantic_map"}
    # the flags are not settings: a process of the stack loads its config with them set
    env = stack_env(port=7447, run_id="r", run_dir=tmp_path, base={}, side="robot")
    assert load_config(env=env).zenoh.side == "all"
