# shellcheck shell=bash
# Keys and certificates with the openssl command, for keystore.sh (SROS2) and
# wan_certs.sh (the WAN mode's TLS). Source it after setting WORK (a scratch directory
# the caller removes).
#
# Keys: EC prime256v1 (PKCS#8 PEM, unencrypted, as sros2), owner-only. Certificates are
# valid from a day ago (as sros2: a peer whose clock is a little behind, or a Pi without
# a real-time clock, still takes them), issued through `openssl ca` so that the start
# can be back-dated.

CERTS_NOW=$(date -u +%s)
# openssl ca's time format, YYYYMMDDHHMMSSZ, for seconds since the epoch
certs_stamp() { date -u -d "@$1" +%Y%m%d%H%M%SZ; }

# certs_new_key FILE: a new key in FILE.
certs_new_key() {
  (umask 077 && openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 \
    -pkeyopt ec_param_enc:named_curve -out "$1" 2>"$WORK/err") || { cat "$WORK/err" >&2; return 1; }
}

# certs_issue CN KEY OUT DAYS EXTENSIONS [CA_CERT CA_KEY]: a certificate for KEY, subject
# CN=CN, valid for DAYS, with the given extension lines (openssl config syntax), signed
# by the CA (self-signed without one), written to OUT (mode 0644).
certs_issue() {
  local cn=$1 key=$2 out=$3 days=$4 ext=$5 ca_cert=${6:-} ca_key=${7:-} w
  w=$(mktemp -d "$WORK/ca.XXXXXX")
  : >"$w/index.txt"
  cat >"$w/ca.cnf" <<CNF
[ca]
default_ca = eezybot
[eezybot]
database = $w/index.txt
new_certs_dir = $w
rand_serial = yes
default_md = sha256
policy = policy_cn
unique_subject = no
copy_extensions = none
email_in_dn = no
[policy_cn]
commonName = supplied
[req]
prompt = no
distinguished_name = dn
[dn]
CN = $cn
[ext]
$ext
CNF
  openssl req -new -key "$key" -config "$w/ca.cnf" -out "$w/req.csr" 2>"$w/err" || { cat "$w/err" >&2; return 1; }
  local sign=(-selfsign -keyfile "$key")
  [ -z "$ca_cert" ] || sign=(-cert "$ca_cert" -keyfile "$ca_key")
  openssl ca -batch -config "$w/ca.cnf" "${sign[@]}" -in "$w/req.csr" -out "$w/cert.pem" \
    -startdate "$(certs_stamp $((CERTS_NOW - 86400)))" -enddate "$(certs_stamp $((CERTS_NOW + days * 86400)))" \
    -extensions ext -notext 2>"$w/err" || { cat "$w/err" >&2; return 1; }
  install -m 0644 "$w/cert.pem" "$out"
}
