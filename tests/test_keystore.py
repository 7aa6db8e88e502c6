"""launch_scripts/keystore.sh (an SROS2 keystore without a ROS install), the SROS2 side
of the launch scripts and deploy/install.sh --keystore (issue 18).

The keystore is checked with the openssl command as DDS Security implementations check
it (sros2's layout and file names, certificates issued by the CA, S/MIME signatures by
the CA), its permissions against the topic contract (tests/data/topics.json), and a real
node is run under its enclaves: accepted under its own, refused under another's."""
import calendar
import hashlib
import os
import re
import shutil
import signal
import subprocess
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import ACTIONS, REPO, SERVICES, TOPICS, bin_path, default_sigint
from launch_script import Script, node_processes, reap_scripts  # noqa: F401 (fixture)

KEYSTORE_SH = REPO / "launch_scripts" / "keystore.sh"
INSTALL_SH = REPO / "deploy" / "install.sh"
ENCLAVE_FILES = ("cert.pem", "key.pem", "identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s",
                 "permissions.p7s", "permissions.xml")
PC_NODES = {"gui_bridge", "compute_ik", "state_publisher", "recorder", "twin"}  # sros2.rs PC_NODES
PI_NODES = {"serial_node", "camera_node"}  # libs/ros_plumbing/src/sros2.rs PI_NODES
# the enclaves keystore.sh makes by default: the nodes' two, and the WAN bridges' two
ENCLAVES = ("/eezybot/pc", "/eezybot/pi", "/eezybot/bridge_pc", "/eezybot/bridge_pi")
# roles that run beside either half, wherever their hardware is (ros_plumbing::sros2::EITHER_HALF):
# a leader arm's reader
EITHER_HALF = {"serial_node (leader)"}


def runs_in(role, nodes):
    """Whether the contract's role `role` (`gui_bridge (record)`) runs in the enclave of `nodes`."""
    return role.split(" ")[0] in nodes or role in EITHER_HALF
NO_SECURITY = {"ROS_SECURITY_ENABLE": "", "ROS_SECURITY_STRATEGY": "", "ROS_SECURITY_KEYSTORE": "",
               "ROS_SECURITY_ENCLAVE_OVERRIDE": ""}


def bin_dir():
    """The directory of our binaries (EEZYBOT_BIN_DIR, default target/debug), which
    keystore.sh takes eezybot_sros2 from."""
    return str(Path(bin_path("eezybot_sros2")).parent)


def keystore_sh(*args, env=None):
    return subprocess.run([str(KEYSTORE_SH), *map(str, args)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "EEZYBOT_BIN_DIR": bin_dir(), **(env or {})})


def openssl(*args, check=True):
    r = subprocess.run(["openssl", *map(str, args)], capture_output=True, text=True, timeout=60)
    if check:
        assert r.returncode == 0, f"openssl {' '.join(map(str, args))}: {r.stdout}{r.stderr}"
    return r


def sha256(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def fingerprint(cert):
    return openssl("x509", "-noout", "-fingerprint", "-sha256", "-in", cert).stdout.strip()


@pytest.fixture(scope="module")
def keystore(tmp_path_factory):
    """One keystore for the module's read-only tests."""
    root = tmp_path_factory.mktemp("ks") / "keystore"
    r = keystore_sh(root)
    assert r.returncode == 0, r.stdout + r.stderr
    return root


@pytest.fixture
def fresh(tmp_path):
    """A keystore of the test's own, to change."""
    root = tmp_path / "keystore"
    r = keystore_sh(root)
    assert r.returncode == 0, r.stdout + r.stderr
    return root


def enclave(root, name):
    return Path(root) / "enclaves" / name.strip("/")


def grant_topics(permissions_xml):
    """(subject, validity, domains element, {publish: set, subscribe: set}) of the single
    grant of a permissions document."""
    dds = ET.parse(permissions_xml).getroot()
    assert dds.tag == "dds"
    grants = dds.findall("permissions/grant")
    assert len(grants) == 1
    g = grants[0]
    assert [c.tag for c in g][:2] == ["subject_name", "validity"] and g[-1].tag == "default"
    assert g.find("default").text == "DENY"
    rules = g.findall("allow_rule")
    assert len(rules) == 1 and not g.findall("deny_rule")
    topics = {kind: {t.text for t in rules[0].findall(f"{kind}/topics/topic")} for kind in ("publish", "subscribe")}
    validity = (g.find("validity/not_before").text, g.find("validity/not_after").text)
    return g.get("name"), g.find("subject_name").text, validity, rules[0].find("domains"), topics


def cert_dates(cert):
    """notBefore / notAfter of a certificate as YYYY-MM-DDThh:mm:ss (UTC)."""
    out = openssl("x509", "-noout", "-startdate", "-enddate", "-in", cert).stdout
    dates = dict(line.split("=", 1) for line in out.strip().splitlines())
    return tuple(time.strftime("%Y-%m-%dT%H:%M:%S", time.strptime(dates[k], "%b %d %H:%M:%S %Y %Z"))
                 for k in ("notBefore", "notAfter"))


# ---------------------------------------------------------------------------------------
# the keystore

def test_the_layout_and_file_names_are_sros2s(keystore):
    """public/, private/, enclaves/ with the file names of `ros2 security create_keystore`
    and `create_enclave`; the *_ca files link to ca.cert.pem / ca.key.pem and each enclave
    links the public CA certificates and the governance, as sros2 does."""
    for d in ("public", "private", "enclaves"):
        assert (keystore / d).is_dir()
    assert (keystore / "public" / "ca.cert.pem").is_file() and not (keystore / "public" / "ca.cert.pem").is_symlink()
    assert (keystore / "private" / "ca.key.pem").is_file()
    for which in ("identity", "permissions"):
        assert os.readlink(keystore / "public" / f"{which}_ca.cert.pem") == "ca.cert.pem"
        assert os.readlink(keystore / "private" / f"{which}_ca.key.pem") == "ca.key.pem"
    for f in ("governance.xml", "governance.p7s"):
        assert (keystore / "enclaves" / f).is_file()
    found = sorted(str(p.parent.relative_to(keystore / "enclaves")) for p in (keystore / "enclaves").rglob("key.pem"))
    assert found == sorted(e.lstrip("/") for e in ENCLAVES)
    for name in ENCLAVES:
        d = enclave(keystore, name)
        assert sorted(p.name for p in d.iterdir()) == sorted(ENCLAVE_FILES)
        assert os.readlink(d / "identity_ca.cert.pem") == "../../../public/identity_ca.cert.pem"
        assert os.readlink(d / "permissions_ca.cert.pem") == "../../../public/permissions_ca.cert.pem"
        assert os.readlink(d / "governance.p7s") == "../../governance.p7s"
        for f in ENCLAVE_FILES:
            assert (d / f).is_file(), f"{d / f} (a dangling link?)"


def test_private_keys_are_owner_only(keystore):
    assert (keystore / "private").stat().st_mode & 0o777 == 0o700
    assert (keystore / "private" / "ca.key.pem").stat().st_mode & 0o777 == 0o600
    for name in ENCLAVES:
        assert (enclave(keystore, name) / "key.pem").stat().st_mode & 0o077 == 0
        assert enclave(keystore, name).stat().st_mode & 0o077 == 0


def test_every_certificate_verifies_against_the_ca_and_names_its_enclave(keystore):
    """The CA is self-signed, CN=sros2CA, CA:TRUE; each enclave's certificate is issued by
    it with subject CN=<enclave>, an EC prime256v1 key matching key.pem, and valid from a
    day ago (a slightly slow clock accepts it) for about ten years."""
    ca = keystore / "public" / "ca.cert.pem"
    openssl("verify", "-CAfile", ca, ca)
    text = openssl("x509", "-noout", "-text", "-in", ca).stdout
    assert "CA:TRUE" in text and "prime256v1" in text
    assert openssl("x509", "-noout", "-subject", "-nameopt", "RFC2253", "-in", ca).stdout.strip() == "subject=CN=sros2CA"
    for name in ENCLAVES:
        d = enclave(keystore, name)
        assert "OK" in openssl("verify", "-CAfile", keystore / "public" / "identity_ca.cert.pem", d / "cert.pem").stdout
        openssl("verify", "-CAfile", d / "identity_ca.cert.pem", d / "cert.pem")
        subject = openssl("x509", "-noout", "-subject", "-nameopt", "RFC2253", "-in", d / "cert.pem").stdout.strip()
        assert subject == f"subject=CN={name}"
        text = openssl("x509", "-noout", "-text", "-in", d / "cert.pem").stdout
        assert "prime256v1" in text and "CA:FALSE" in text and "ecdsa-with-SHA256" in text
        assert (openssl("x509", "-noout", "-pubkey", "-in", d / "cert.pem").stdout
                == openssl("pkey", "-pubout", "-in", d / "key.pem").stdout)
        assert "BEGIN PRIVATE KEY" in (d / "key.pem").read_text()  # PKCS#8, unencrypted, as sros2
        start, end = cert_dates(d / "cert.pem")
        now = time.time()
        start_s = calendar.timegm(time.strptime(start, "%Y-%m-%dT%H:%M:%S"))
        end_s = calendar.timegm(time.strptime(end, "%Y-%m-%dT%H:%M:%S"))
        assert now - 86400 - 120 < start_s < now - 86400 + 120, start
        assert 3649 * 86400 < end_s - now < 3651 * 86400, end


def test_governance_and_permissions_are_signed_by_the_ca(keystore, tmp_path):
    """openssl smime -verify against the permissions CA gives back exactly the XML next to
    each .p7s; a changed document no longer verifies."""
    ca = keystore / "public" / "permissions_ca.cert.pem"
    pairs = [(keystore / "enclaves" / "governance.p7s", keystore / "enclaves" / "governance.xml")]
    pairs += [(enclave(keystore, n) / "permissions.p7s", enclave(keystore, n) / "permissions.xml")
              for n in ENCLAVES]
    for p7s, xml in pairs:
        out = tmp_path / "content"
        openssl("smime", "-verify", "-text", "-in", p7s, "-CAfile", ca, "-out", out)
        assert out.read_bytes().replace(b"\r\n", b"\n") == xml.read_bytes(), p7s
        head = p7s.read_text()
        assert "multipart/signed" in head and "Content-Type: text/plain" in head and "sha-256" in head
    forged = tmp_path / "forged.p7s"
    forged.write_text((enclave(keystore, "/eezybot/pi") / "permissions.p7s").read_text()
                      .replace("<default>DENY</default>", "<default>ALLOW</default>"))
    assert openssl("smime", "-verify", "-in", forged, "-CAfile", ca, "-out", tmp_path / "x", check=False).returncode != 0


def test_the_governance_requires_authentication_and_encrypts(keystore):
    """sros2's default governance: no unauthenticated participant, join access control,
    discovery and liveliness encrypted, RTPS signed, read/write access control and
    encrypted data and metadata on every topic; every ROS domain (0 ... 230: sros2's range,
    the most Cyclone DDS's access control takes)."""
    dds = ET.parse(keystore / "enclaves" / "governance.xml").getroot()
    rules = dds.findall("domain_access_rules/domain_rule")
    assert len(rules) == 1
    r = rules[0]
    assert r.find("domains/id_range/min").text == "0" and r.find("domains/id_range/max").text == "230"
    expect = {"allow_unauthenticated_participants": "false", "enable_join_access_control": "true",
              "discovery_protection_kind": "ENCRYPT", "liveliness_protection_kind": "ENCRYPT",
              "rtps_protection_kind": "SIGN"}
    assert {k: r.find(k).text for k in expect} == expect
    topic_rules = r.findall("topic_access_rules/topic_rule")
    assert len(topic_rules) == 1
    t = topic_rules[0]
    expect = {"topic_expression": "*", "enable_discovery_protection": "true", "enable_liveliness_protection": "true",
              "enable_read_access_control": "true", "enable_write_access_control": "true",
              "metadata_protection_kind": "ENCRYPT", "data_protection_kind": "ENCRYPT"}
    assert {k: t.find(k).text for k in expect} == expect


def test_the_pi_may_publish_servo_state_and_not_xyz_target(keystore):
    """The Pi's grant (subject CN=/eezybot/pi, the certificate's validity) lets serial_node
    publish servo_state and diagnostics and nothing the PC publishes; the PC's lets it
    publish the targets."""
    name, subject, validity, domains, pi = grant_topics(enclave(keystore, "/eezybot/pi") / "permissions.xml")
    assert (name, subject) == ("/eezybot/pi", "CN=/eezybot/pi")
    assert validity == cert_dates(enclave(keystore, "/eezybot/pi") / "cert.pem")
    assert domains.find("id_range/min").text == "0" and domains.find("id_range/max").text == "230"
    assert {"rt/servo_state", "rt/diagnostics"} <= pi["publish"]
    for t in ("rt/xyz_target", "rt/xyz_line_target", "rt/gripper_target", "rt/joint_target", "rt/estop",
              "rt/servo_angles", "rt/joint_states", "rt/tf", "rt/robot_description"):
        assert t not in pi["publish"], t
    assert {"rt/servo_angles", "rt/estop"} <= pi["subscribe"]
    assert not {"rt/xyz_target", "rt/xyz_line_target"} & pi["subscribe"]
    assert not any("compute_ik" in t for t in pi["publish"] | pi["subscribe"])
    _, subject, _, _, pc = grant_topics(enclave(keystore, "/eezybot/pc") / "permissions.xml")
    assert subject == "CN=/eezybot/pc"
    assert {"rt/xyz_target", "rt/xyz_line_target", "rt/gripper_target", "rt/joint_target", "rt/estop",
            "rt/servo_angles"} <= pc["publish"]
    assert {"rt/xyz_target", "rt/xyz_line_target"} <= pc["subscribe"]
    assert "rt/servo_state" not in pc["publish"] and "rt/servo_state" in pc["subscribe"]


def test_every_contract_topic_is_granted_exactly_to_the_enclaves_of_its_nodes(keystore):
    """For each topic of tests/data/topics.json: an enclave may publish (subscribe) it
    exactly when one of its nodes does; for each action and service, it may take the
    requests (send them) exactly when one of its nodes serves (calls) it; besides, each
    may use its nodes' parameter services, gui_bridge's calls of compute_ik's, and the
    ROS graph topics."""
    grants = {n: grant_topics(enclave(keystore, n) / "permissions.xml")[4] for n in ("/eezybot/pc", "/eezybot/pi")}
    nodes = {"/eezybot/pc": PC_NODES, "/eezybot/pi": PI_NODES}
    covered = set()
    for name, t in TOPICS.items():
        for e, g in grants.items():
            for kind, roles in (("publish", t["publishers"]), ("subscribe", t["subscribers"])):
                ours = any(runs_in(r, nodes[e]) for r in roles)
                assert (f"rt/{name}" in g[kind]) == ours, (e, kind, name)
                if f"rt/{name}" in g[kind]:
                    covered.add(name)
    assert covered == set(TOPICS)
    callables = [(f"{a}/_action/{s}", c) for a, c in ACTIONS.items() for s in ("send_goal", "cancel_goal", "get_result")]
    callables += list(SERVICES.items())
    # two actions (the controllers'), the controller manager's two services, the recorder's three
    assert len(callables) == 3 * 2 + 2 + 3, callables
    for name, c in callables:
        for e, g in grants.items():
            serves = any(runs_in(r, nodes[e]) for r in c["servers"])
            calls = any(runs_in(r, nodes[e]) for r in c["clients"])
            assert (f"rq/{name}Request" in g["subscribe"] and f"rr/{name}Reply" in g["publish"]) == serves, (e, name)
            assert (f"rq/{name}Request" in g["publish"] and f"rr/{name}Reply" in g["subscribe"]) == calls, (e, name)
    srv = ["describe_parameters", "get_parameters", "get_parameter_types", "list_parameters", "set_parameters",
           "set_parameters_atomically"]
    for e, g in grants.items():
        for node in nodes[e]:
            for s in srv:
                assert f"rq/{node}/{s}Request" in g["subscribe"] and f"rr/{node}/{s}Reply" in g["publish"]
        assert {"ros_discovery_info", "rt/parameter_events", "rt/rosout"} <= g["publish"]
        assert {"ros_discovery_info", "rt/parameter_events", "rt/clock"} <= g["subscribe"]
        contract = {f"rt/{n}" for n in TOPICS}
        services = {t for t in g["publish"] | g["subscribe"] if t.startswith(("rq/", "rr/"))}
        graph = {"ros_discovery_info", "rt/parameter_events", "rt/rosout", "rt/clock"}
        # the actions' feedback and status, published by compute_ik's controllers, on the PC only
        actions = {f"rt/{a}/_action/{t}" for a in ACTIONS for t in ("feedback", "status")}
        assert (g["publish"] & actions) == (actions if e == "/eezybot/pc" else set()), e
        assert {"rt/leader/joint_states", "rt/leader/deadman"} <= g["publish"], e  # a leader's reader on either
        assert g["publish"] | g["subscribe"] <= contract | services | graph | actions, e
    pc = grants["/eezybot/pc"]
    # the recorder's episode services: served by the recorder, called by gui_bridge's Record card (issue 34)
    for s in ("start_episode", "save_episode", "discard_episode"):
        assert {f"rq/recorder/{s}Request", f"rr/recorder/{s}Reply"} <= pc["subscribe"] | pc["publish"]
        assert f"rq/recorder/{s}Request" in pc["publish"] and f"rq/recorder/{s}Request" in pc["subscribe"]
    assert "rq/recorder/set_parametersRequest" in pc["publish"]  # the card sets the recorder's task
    assert "rq/recorder/set_parametersRequest" not in grants["/eezybot/pi"]["publish"]
    assert "rq/compute_ik/set_parametersRequest" in pc["publish"]
    assert "rr/compute_ik/set_parametersReply" in pc["subscribe"]
    # the calibration wizard applies a saved calibration: serial_node's arm_config
    assert "rq/serial_node/set_parametersRequest" in pc["publish"]
    assert "rq/serial_node/set_parametersRequest" in grants["/eezybot/pi"]["subscribe"]
    assert "rq/arm_controller/follow_joint_trajectory/_action/send_goalRequest" in pc["subscribe"]
    assert "rr/gripper_controller/gripper_cmd/_action/get_resultReply" in pc["publish"]
    # ros2_control's controller manager interface, served by compute_ik (issue 33)
    for s in ("list_controllers", "switch_controller"):
        assert f"rq/controller_manager/{s}Request" in pc["subscribe"]
        assert f"rr/controller_manager/{s}Reply" in pc["publish"]
        assert not {f"rq/controller_manager/{s}Request", f"rr/controller_manager/{s}Reply"} & (
            grants["/eezybot/pi"]["publish"] | grants["/eezybot/pi"]["subscribe"])


def test_a_rerun_keeps_the_ca_the_governance_and_the_enclaves(fresh):
    files = [fresh / "public" / "ca.cert.pem", fresh / "private" / "ca.key.pem", fresh / "enclaves" / "governance.p7s"]
    for n in ENCLAVES:
        files += [enclave(fresh, n) / f for f in ("cert.pem", "key.pem", "permissions.p7s", "permissions.xml")]
    before = {f: sha256(f) for f in files}
    ca = fingerprint(fresh / "public" / "ca.cert.pem")
    r = keystore_sh(fresh)
    assert r.returncode == 0, r.stderr
    assert {f: sha256(f) for f in files} == before
    assert fingerprint(fresh / "public" / "ca.cert.pem") == ca
    assert "CA: kept" in r.stderr and "enclave /eezybot/pi: kept" in r.stderr


def test_a_rerun_adds_the_bridges_enclaves_to_a_keystore_made_without_them(fresh):
    """A keystore made before the WAN bridges had enclaves (only /eezybot/pc and
    /eezybot/pi): `keystore.sh DIR` again adds /eezybot/bridge_pc and /eezybot/bridge_pi,
    signed by the same CA, each with the role of its name (what its site's bridge
    carries), and keeps the rest. A second site's bridge enclave takes `--role`."""
    for name in ("/eezybot/bridge_pc", "/eezybot/bridge_pi"):
        shutil.rmtree(enclave(fresh, name))
    kept = {f: sha256(f) for n in ("/eezybot/pc", "/eezybot/pi") for f in enclave(fresh, n).glob("*.p*")}
    r = keystore_sh(fresh)
    assert r.returncode == 0, r.stderr
    assert {f: sha256(f) for f in kept} == kept
    grants = {}
    for name in ("/eezybot/bridge_pc", "/eezybot/bridge_pi"):
        d = enclave(fresh, name)
        assert f"enclave {name}: created" in r.stderr, r.stderr
        openssl("verify", "-CAfile", fresh / "public" / "ca.cert.pem", d / "cert.pem")
        grants[name] = grant_topics(d / "permissions.xml")[4]
    pc, pi = grants["/eezybot/bridge_pc"], grants["/eezybot/bridge_pi"]
    # what one site's bridge reads from its nodes, the other's writes to its own: the
    # Pi's servo_state out, the PC's servo_angles out; no target and no service crosses
    assert "rt/servo_state" in pi["subscribe"] and "rt/servo_state" in pc["publish"]
    assert "rt/servo_angles" in pc["subscribe"] and "rt/servo_angles" in pi["publish"]
    for g in (pc, pi):
        assert not {t for t in g["publish"] | g["subscribe"] if t.startswith(("rq/", "rr/")) or "target" in t}
        assert "ros_discovery_info" in g["publish"] and "ros_discovery_info" in g["subscribe"]
    assert keystore_sh(fresh, "--enclave", "/eezybot/bridge_pc2", "--role", "bridge_pc").returncode == 0
    assert grant_topics(enclave(fresh, "/eezybot/bridge_pc2") / "permissions.xml")[4] == pc


def test_enclave_adds_one_more_signed_by_the_same_ca(fresh):
    """--enclave /eezybot/pc2 (a second operator PC) gets the PC's permissions by default;
    --role pi the Pi's, --role tools every contract topic and every service; the CA and the
    other enclaves stay."""
    ca = fingerprint(fresh / "public" / "ca.cert.pem")
    pi_cert = sha256(enclave(fresh, "/eezybot/pi") / "cert.pem")
    r = keystore_sh(fresh, "--enclave", "/eezybot/pc2")
    assert r.returncode == 0, r.stderr
    assert keystore_sh(fresh, "--enclave", "/eezybot/pi2", "--role", "pi").returncode == 0
    assert keystore_sh(fresh, "--enclave", "/eezybot/tools", "--role", "tools").returncode == 0
    assert fingerprint(fresh / "public" / "ca.cert.pem") == ca
    assert sha256(enclave(fresh, "/eezybot/pi") / "cert.pem") == pi_cert
    for name in ("/eezybot/pc2", "/eezybot/pi2", "/eezybot/tools"):
        d = enclave(fresh, name)
        openssl("verify", "-CAfile", fresh / "public" / "ca.cert.pem", d / "cert.pem")
        openssl("smime", "-verify", "-in", d / "permissions.p7s", "-CAfile", fresh / "public" / "ca.cert.pem",
                "-out", os.devnull)
        assert grant_topics(d / "permissions.xml")[1] == f"CN={name}"
    pc2 = grant_topics(enclave(fresh, "/eezybot/pc2") / "permissions.xml")[4]
    pc = grant_topics(enclave(fresh, "/eezybot/pc") / "permissions.xml")[4]
    assert pc2 == pc
    pi2 = grant_topics(enclave(fresh, "/eezybot/pi2") / "permissions.xml")[4]
    assert "rt/servo_state" in pi2["publish"] and "rt/xyz_target" not in pi2["publish"]
    tools = grant_topics(enclave(fresh, "/eezybot/tools") / "permissions.xml")[4]
    assert {f"rt/{n}" for n in TOPICS} <= tools["publish"] & tools["subscribe"]
    assert {"rq/*", "rr/*"} <= tools["publish"] & tools["subscribe"] and "rt/rosout" in tools["subscribe"]


def test_namespace_and_domain_shape_the_permissions(fresh):
    """--namespace /arm2 (nodes run with -r __ns:=/arm2) moves the topics and services
    under rt/arm2/, rq/arm2/...; /rosout, /parameter_events and /clock stay absolute;
    --domain 7 grants domain 7 only."""
    r = keystore_sh(fresh, "--enclave", "/arm2/pi", "--role", "pi", "--namespace", "/arm2", "--domain", "7")
    assert r.returncode == 0, r.stderr
    _, _, _, domains, g = grant_topics(enclave(fresh, "/arm2/pi") / "permissions.xml")
    assert [d.text for d in domains.findall("id")] == ["7"] and domains.find("id_range") is None
    assert "rt/arm2/servo_state" in g["publish"] and "rt/servo_state" not in g["publish"]
    assert "rq/arm2/serial_node/get_parametersRequest" in g["subscribe"]
    assert {"rt/rosout", "rt/parameter_events"} <= g["publish"] and "rt/clock" in g["subscribe"]


def test_renew_rewrites_the_permissions_and_keeps_keys_and_certificates(fresh):
    d = enclave(fresh, "/eezybot/pi")
    key, cert = sha256(d / "key.pem"), sha256(d / "cert.pem")
    r = keystore_sh(fresh, "--enclave", "/eezybot/pi", "--namespace", "/arm3", "--renew")
    assert r.returncode == 0, r.stderr
    assert (sha256(d / "key.pem"), sha256(d / "cert.pem")) == (key, cert)
    assert "rt/arm3/servo_state" in grant_topics(d / "permissions.xml")[4]["publish"]
    openssl("smime", "-verify", "-in", d / "permissions.p7s", "-CAfile", fresh / "public" / "ca.cert.pem",
            "-out", os.devnull)


def test_no_new_ca_is_made_over_existing_enclaves(fresh):
    """A keystore that lost its CA key: a new CA would orphan every enclave, so the script
    refuses (exit 1) and changes nothing."""
    (fresh / "private" / "ca.key.pem").unlink()
    cert = sha256(fresh / "public" / "ca.cert.pem")
    r = keystore_sh(fresh)
    assert r.returncode == 1, r.stderr
    assert "refusing to make a new CA" in r.stderr
    assert sha256(fresh / "public" / "ca.cert.pem") == cert and not (fresh / "private" / "ca.key.pem").exists()


@pytest.mark.parametrize("args", [[], ["--enclave", "/eezybot/x"], ["{dir}", "--role", "ops"],
                                  ["{dir}", "--domain", "231"], ["{dir}", "--domain", "x"], ["{dir}", "--frobnicate"],
                                  ["{dir}", "--enclave", "eezybot/pc2"], ["{dir}", "--enclave", "/eezybot/pc-2"],
                                  ["{dir}", "--enclave"], ["{dir}", "--namespace", "arm2"], ["{dir}", "{dir}2"],
                                  ["{file}"], ["{dir}", "--role", "pi"]],
                         ids=["no_dir", "no_dir_with_enclave", "bad_role", "domain_231", "domain_text", "unknown_option",
                              "relative_enclave", "dash_in_enclave", "enclave_without_value", "relative_namespace",
                              "two_dirs", "dir_is_a_file", "role_without_enclave"])
def test_bad_usage_exits_2_and_makes_nothing(args, tmp_path):
    (tmp_path / "file").write_text("")
    argv = [a.format(dir=tmp_path / "ks", file=tmp_path / "file") for a in args]
    r = keystore_sh(*argv)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "[keystore.sh]" in r.stderr and "usage:" in r.stderr
    assert not (tmp_path / "ks").exists()


def test_help_exits_0():
    r = keystore_sh("--help")
    assert r.returncode == 0 and "--enclave PATH" in r.stdout and "--role ROLE" in r.stdout


# ---------------------------------------------------------------------------------------
# our nodes under its enclaves

# How long nodes may take to say they are ready (a secured start of debug builds on a
# busy host takes a few seconds): it only bounds a failure.
READY_TIMEOUT = 30.0
READY = " ready in ROS domain "


def wait_ready(read, proc, n, timeout=READY_TIMEOUT):
    """Until `n` nodes have said they are ready in `read()` (the log so far), or `proc`
    exited, or the timeout: whether they did."""
    end = time.monotonic() + timeout
    while read().count(READY) < n and proc.poll() is None and time.monotonic() < end:
        time.sleep(0.1)
    return read().count(READY) >= n


def test_a_node_runs_under_its_enclave_and_is_refused_under_another(keystore, domain, tmp_path):
    """serial_node under /eezybot/pi with Enforce starts secured: it says it is ready
    (every endpoint made, access control passed) and runs until Ctrl-C stops it with 0;
    under /eezybot/pc it may not serve its own parameter services (rq/serial_node/...),
    which access control refuses: it stops with the topic named."""
    env = {**os.environ, **NO_SECURITY, "ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
           "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": str(keystore)}
    exe = bin_path("serial_node")
    log = tmp_path / "serial_node.log"
    with open(log, "w") as out_file:
        ok = subprocess.Popen([exe, "--ros-args", "-p", "port:=mock", "--enclave", "/eezybot/pi"], env=env,
                              stdout=out_file, stderr=subprocess.STDOUT, preexec_fn=default_sigint)
    try:
        ready = wait_ready(log.read_text, ok, 1)
        running = ok.poll() is None
    finally:
        ok.send_signal(signal.SIGINT)
        ok.wait(20)
    out = log.read_text()
    assert ready and running, f"serial_node under /eezybot/pi: ready {ready}, still running {running}\n{out}"
    assert ok.returncode == 0, out
    assert "/eezybot/pi" in out, out
    bad = subprocess.run([exe, "--ros-args", "-p", "port:=mock", "--enclave", "/eezybot/pc"], env=env,
                         capture_output=True, text=True, timeout=30)
    assert bad.returncode != 0
    assert "rq/serial_node/" in bad.stdout + bad.stderr, bad.stdout + bad.stderr


# ---------------------------------------------------------------------------------------
# launch scripts

class KeystoreScript(Script):
    """A launch script with security off unless `env` turns it on, on the virtual Arduino."""

    def __init__(self, name, env, *args):
        super().__init__(name, *args, env={**NO_SECURITY, "SERIAL_PORT": "mock", **env}, log_prefix="keystore-")


def enclave_of(argv):
    """The value of --enclave in a node's argv, or None."""
    return argv[argv.index("--enclave") + 1] if "--enclave" in argv else None


@pytest.mark.parametrize("script,expect", [
    ("run_graph.sh", {"compute_ik": "/eezybot/pc", "state_publisher": "/eezybot/pc", "gui_bridge": "/eezybot/pc",
                      "serial_node": "/eezybot/pi"}),
    ("pc.sh", {"compute_ik": "/eezybot/pc", "state_publisher": "/eezybot/pc", "gui_bridge": "/eezybot/pc"}),
    ("pi.sh", {"serial_node": "/eezybot/pi"}),
])
def test_scripts_give_each_node_its_enclave_and_say_security_is_on(script, expect, keystore, domain):
    """ROS_SECURITY_ENABLE=true: the script says security is on (keystore, enclave,
    strategy), each node runs with --enclave of its machine and says it is ready under
    Enforce (the keystore is good), and Ctrl-C stops them with 0."""
    s = KeystoreScript(script, {"ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
                        "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": str(keystore)},
               "--log-level", "info")
    try:
        found = s.nodes(len(expect))
        assert {n: enclave_of(a) for n, a in found.items()} == expect
        for argv in found.values():
            assert argv[-2:] == ["--log-level", "info"], argv  # the user's arguments still come last
        # every node said it is ready (its endpoints made: access control passed) and the
        # script still runs; a node that failed would also fail the exit status below
        # (a node that never got ready here was patches/README.md's rustdds entry 33)
        assert wait_ready(s.output, s.proc, len(expect)), f"not every node said it is ready:\n{s.output()}"
        assert s.proc.poll() is None, s.output()
        out = s.output()
        for e in set(expect.values()):
            assert f"security on: keystore {keystore}, enclave {e} for" in out, out
        assert "strategy Enforce" in out
    finally:
        code = s.stop()
    assert code == 0, s.output()


@pytest.mark.parametrize("script", ["run_graph.sh", "pc.sh", "pi.sh"])
def test_enforce_without_the_enclave_exits_2_before_starting_anything(script, tmp_path, domain):
    """An empty keystore directory under Enforce: the script names the missing enclave
    directory and exits 2 without starting a node; without a keystore at all it names
    ROS_SECURITY_KEYSTORE."""
    (tmp_path / "empty").mkdir()
    for keystore, says in ((str(tmp_path / "empty"), f"{tmp_path / 'empty'}/enclaves/eezybot/p"),
                           ("", "ROS_SECURITY_KEYSTORE is not set")):
        s = KeystoreScript(script, {"ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
                            "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": keystore})
        try:
            code = s.proc.wait(30)
            assert not node_processes(s.proc.pid)
        finally:
            s.stop()
        assert code == 2, s.output()
        assert says in s.output() and "not starting unsecured" in s.output(), s.output()
        assert "running here" not in s.output()


def test_enforce_names_a_missing_enclave_file(fresh, domain):
    (enclave(fresh, "/eezybot/pi") / "permissions.p7s").unlink()
    s = KeystoreScript("pi.sh", {"ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
                         "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": str(fresh)})
    try:
        code = s.proc.wait(30)
    finally:
        s.stop()
    assert code == 2
    assert f"{enclave(fresh, '/eezybot/pi')}/permissions.p7s is missing" in s.output(), s.output()


def test_permissive_without_a_keystore_warns_and_runs(tmp_path, domain):
    """Any strategy but Enforce: a missing keystore is a warning; the node starts (and,
    as rcl, runs unsecured)."""
    s = KeystoreScript("pi.sh", {"ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": "true",
                         "ROS_SECURITY_STRATEGY": "Permissive", "ROS_SECURITY_KEYSTORE": str(tmp_path / "none")})
    try:
        found = s.nodes(1)
        assert enclave_of(found["serial_node"]) == "/eezybot/pi"
        assert "WARNING: ROS_SECURITY_STRATEGY=Permissive is not Enforce" in s.output()
    finally:
        code = s.stop()
    assert code == 0, s.output()


@pytest.mark.parametrize("value", ["", "1", "True"])
def test_security_not_enabled_changes_nothing(value, domain):
    """ROS_SECURITY_ENABLE unset, or anything but exactly `true` (rcl): no --enclave, no
    security line; a value that looks meant to enable it is warned about."""
    s = KeystoreScript("pi.sh", {"ROS_DOMAIN_ID": str(domain), "ROS_SECURITY_ENABLE": value,
                         "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": "/nonexistent"})
    try:
        found = s.nodes(1)
        assert "--enclave" not in found["serial_node"]
        assert "security on" not in s.output()
        assert ("is not `true`: security is off" in s.output()) == bool(value), s.output()
    finally:
        code = s.stop()
    assert code == 0, s.output()


# ---------------------------------------------------------------------------------------
# deploy/install.sh --keystore

@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (install.sh installs into /etc)")
def test_install_keystore_copies_the_pi_enclave_owner_only_and_turns_security_on(keystore, tmp_path):
    """A keystore copied as the README says (rsync -L: links resolved, only
    enclaves/eezybot/pi) installed under DESTDIR: the six files plus permissions.xml in
    /etc/eezybot/keystore/enclaves/eezybot/pi, key.pem 0400, directories 0700, and
    ROS_SECURITY_* in /etc/default/eezybot (replacing the example's commented lines)."""
    copy = tmp_path / "copy" / "enclaves" / "eezybot" / "pi"
    shutil.copytree(enclave(keystore, "/eezybot/pi"), copy, symlinks=False)
    root = tmp_path / "root"
    (root / "etc" / "default").mkdir(parents=True)
    shutil.copy(REPO / "deploy" / "eezybot.env.example", root / "etc" / "default" / "eezybot")
    r = subprocess.run([str(INSTALL_SH), "--keystore", str(tmp_path / "copy")], capture_output=True, text=True,
                       env={**os.environ, "DESTDIR": str(root)}, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    dst = root / "etc" / "eezybot" / "keystore" / "enclaves" / "eezybot" / "pi"
    assert sorted(p.name for p in dst.iterdir()) == sorted(ENCLAVE_FILES)
    for f in ENCLAVE_FILES:
        assert not (dst / f).is_symlink() and sha256(dst / f) == sha256(copy / f)
    assert (dst / "key.pem").stat().st_mode & 0o777 == 0o400
    d = dst
    while d != root / "etc" / "eezybot":
        assert d.stat().st_mode & 0o777 == 0o700, d
        d = d.parent
    env = (root / "etc" / "default" / "eezybot").read_text()
    for line in ("ROS_SECURITY_ENABLE=true", "ROS_SECURITY_STRATEGY=Enforce",
                 "ROS_SECURITY_KEYSTORE=/etc/eezybot/keystore"):
        assert re.search(f"^{line}$", env, re.M), env
        assert len(re.findall(f"^#? *{line.split('=')[0]}=", env, re.M)) == 1, env
    assert "ROS_DOMAIN_ID=0" in env  # the rest of the file is kept
    # again (an update): same result, the enclave replaced, not nested
    r = subprocess.run([str(INSTALL_SH), "--keystore", str(copy)], capture_output=True, text=True,
                       env={**os.environ, "DESTDIR": str(root)}, timeout=60)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in dst.iterdir()) == sorted(ENCLAVE_FILES)
    assert (root / "etc" / "default" / "eezybot").read_text() == env


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root (install.sh installs into /etc)")
def test_install_keystore_refuses_a_bad_enclave(keystore, tmp_path):
    """Links not resolved when copying (a dangling identity_ca.cert.pem), a certificate of
    another keystore's CA, or no such directory: nothing is installed."""
    root = tmp_path / "root"
    env = {**os.environ, "DESTDIR": str(root)}
    dangling = tmp_path / "dangling"
    shutil.copytree(enclave(keystore, "/eezybot/pi"), dangling, symlinks=True)
    r = subprocess.run([str(INSTALL_SH), "--keystore", str(dangling)], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 1 and "identity_ca.cert.pem is missing" in r.stderr, r.stderr
    other = tmp_path / "other"
    assert keystore_sh(other).returncode == 0
    mixed = tmp_path / "mixed"
    shutil.copytree(enclave(keystore, "/eezybot/pi"), mixed)
    (mixed / "identity_ca.cert.pem").unlink()
    shutil.copy(other / "public" / "ca.cert.pem", mixed / "identity_ca.cert.pem")
    r = subprocess.run([str(INSTALL_SH), "--keystore", str(mixed)], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 1 and "is not issued by" in r.stderr, r.stderr
    r = subprocess.run([str(INSTALL_SH), "--keystore", str(tmp_path / "nothing")], capture_output=True, text=True,
                       env=env, timeout=60)
    assert r.returncode == 2
    assert not (root / "etc" / "eezybot").exists()
