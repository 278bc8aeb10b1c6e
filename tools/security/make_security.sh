#!/usr/bin/env bash
# Creates a DDS Security directory for poise (Fast DDS builtin plugins PKI-DH, Access-Permissions,
# AES-GCM-GMAC): a CA, one identity per host, a signed governance (join access control, encrypted
# discovery and data) and signed per-host permissions (who may publish / subscribe which topic).
#
# Usage: tools/security/make_security.sh OUT_DIR [HOST...]
#   HOST defaults to: imu camera fusion recorder. Other host names (e.g. a discovery server, a
#   monitoring tool) may join the domains but neither publish nor subscribe anything.
# Options (environment):
#   POISE_SEC_ORG      organisation in the subject names (default "poise")
#   POISE_SEC_DOMAINS  domain id range "MIN-MAX" the rules apply to (default 0-232)
#   POISE_SEC_DAYS     certificate validity in days (default 3650)
#   POISE_SEC_GRANTS   "per-topic" (default): each host's permissions list its topics (below);
#                      "opaque": the permissions name no topic (publish and/or subscribe "*"), so
#                      the permissions document every host sends in clear in the authentication
#                      handshake reveals no topic name. Cost: access control no longer limits
#                      which topics a host of this CA may use (the camera host could publish imu);
#                      strangers are still kept out by authentication and encryption.
#
# Layout written (what poise_dds reads with POISE_SECURITY_DIR=OUT_DIR POISE_SECURITY_IDENTITY=HOST):
#   OUT_DIR/ca.pem ca.key            the CA (identity CA and permissions CA); keep ca.key offline
#   OUT_DIR/governance.xml .p7s      domain rules, signed by the CA
#   OUT_DIR/HOST/cert.pem key.pem    the host identity (EC P-256), signed by the CA
#   OUT_DIR/HOST/permissions.xml .p7s  the host's grant, signed by the CA
# Copy to each machine only ca.pem, governance.p7s and that machine's HOST/ directory.
#
# Topic rules, per-topic grants (default DENY for everything not listed):
#   imu       publish imu, vehicle_input, diagnostics
#   camera    publish tag_detections, vision_pose, diagnostics
#   fusion    subscribe imu, vehicle_input, tag_detections, vision_pose;
#             publish attitude/*, pose/*, altitude, diagnostics
#   recorder  subscribe * (everything)
# Opaque grants: imu, camera publish *; fusion publish and subscribe *; recorder subscribe *.
# Any other host name: no topic, with either kind.
set -euo pipefail

if [[ $# -lt 1 || "$1" == "-h" || "$1" == "--help" ]]; then
  sed -n '2,34p' "$0" | sed 's/^# \{0,1\}//'
  [[ $# -lt 1 ]] && exit 2 || exit 0
fi
command -v openssl >/dev/null || { echo "make_security.sh: openssl not found (apt-get install openssl)" >&2; exit 1; }

out=$1
shift
hosts=("$@")
[[ ${#hosts[@]} -eq 0 ]] && hosts=(imu camera fusion recorder)
org=${POISE_SEC_ORG:-poise}
domains=${POISE_SEC_DOMAINS:-0-232}
days=${POISE_SEC_DAYS:-3650}
grants=${POISE_SEC_GRANTS:-per-topic}
if [[ $grants != per-topic && $grants != opaque ]]; then
  echo "make_security.sh: POISE_SEC_GRANTS must be per-topic or opaque, got '$grants'" >&2
  exit 2
fi
dmin=${domains%-*}
dmax=${domains#*-}
if ! [[ $dmin =~ ^[0-9]+$ && $dmax =~ ^[0-9]+$ ]] || (( dmin > dmax || dmax > 232 )); then
  echo "make_security.sh: POISE_SEC_DOMAINS must be MIN-MAX within 0-232, got '$domains'" >&2
  exit 2
fi
for h in "${hosts[@]}"; do
  [[ $h =~ ^[A-Za-z0-9_-]+$ ]] || { echo "make_security.sh: bad host name '$h' (letters, digits, _ -)" >&2; exit 2; }
done

mkdir -p "$out"
out=$(cd "$out" && pwd)
umask 077

# --- CA ------------------------------------------------------------------------------------------
# The CA also signs governance/permissions as S/MIME: its keyUsage must include digitalSignature,
# or PKCS7_verify rejects it ("unsuitable certificate purpose") and Fast DDS fails silently.
if [[ ! -f $out/ca.pem ]]; then
  openssl ecparam -name prime256v1 -genkey -noout -out "$out/ca.key" 2>/dev/null
  openssl req -x509 -new -key "$out/ca.key" -sha256 -days "$days" -subj "/C=XX/O=$org/CN=$org CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature" \
    -out "$out/ca.pem"
fi

sign() {  # sign XML with the CA as S/MIME (text mode, as the DDS Security builtin plugins expect)
  openssl smime -sign -text -in "$1" -out "$2" -signer "$out/ca.pem" -inkey "$out/ca.key"
  # Verify as Fast DDS will (it only says "participant creation failed" otherwise).
  if ! openssl smime -verify -text -in "$2" -CAfile "$out/ca.pem" -out /dev/null 2>/dev/null; then
    echo "make_security.sh: $2 does not verify against $out/ca.pem" >&2
    exit 1
  fi
}

# --- Governance ----------------------------------------------------------------------------------
cat > "$out/governance.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>$dmin</min><max>$dmax</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
sign "$out/governance.xml" "$out/governance.p7s"

# --- Identities and permissions ------------------------------------------------------------------
topics_xml() {  # $1 = publish|subscribe, rest = topic expressions
  local kind=$1
  shift
  [[ $# -eq 0 ]] && return 0
  echo "        <$kind><topics>"
  for t in "$@"; do echo "          <topic>$t</topic>"; done
  echo "        </topics></$kind>"
}

for h in "${hosts[@]}"; do
  d=$out/$h
  mkdir -p "$d"
  if [[ ! -f $d/cert.pem ]]; then
    openssl ecparam -name prime256v1 -genkey -noout -out "$d/key.pem" 2>/dev/null
    openssl req -new -key "$d/key.pem" -subj "/C=XX/O=$org/CN=$h" -out "$d/cert.csr"
    openssl x509 -req -in "$d/cert.csr" -CA "$out/ca.pem" -CAkey "$out/ca.key" -CAcreateserial \
      -sha256 -days "$days" -out "$d/cert.pem" 2>/dev/null
    rm -f "$d/cert.csr"
  fi
  # RFC 2253 order (CN first): Fast DDS 2.9 compares it with the certificate's subject.
  subject=$(openssl x509 -in "$d/cert.pem" -noout -subject -nameopt RFC2253 | sed 's/^subject=//')
  case $h in
    imu) pub=(imu vehicle_input diagnostics); sub=() ;;
    camera) pub=(tag_detections vision_pose diagnostics); sub=() ;;
    fusion) pub=('attitude/*' 'pose/*' altitude diagnostics)
            sub=(imu vehicle_input tag_detections vision_pose) ;;
    recorder) pub=(); sub=('*') ;;
    *) pub=(); sub=() ;;
  esac
  if [[ $grants == opaque ]]; then  # the same directions, no topic names
    if (( ${#pub[@]} > 0 )); then pub=('*'); fi
    if (( ${#sub[@]} > 0 )); then sub=('*'); fi
  fi
  {
    cat <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="${h}_grant">
      <subject_name>$subject</subject_name>
      <validity>
        <not_before>2020-01-01T00:00:00</not_before>
        <not_after>2099-12-31T23:59:59</not_after>
      </validity>
XML
    # Every host may join the domains (a participant needs a rule for its domain); the topics
    # listed are all it may use.
    echo "      <allow_rule>"
    echo "        <domains><id_range><min>$dmin</min><max>$dmax</max></id_range></domains>"
    topics_xml publish "${pub[@]}"
    topics_xml subscribe "${sub[@]}"
    echo "      </allow_rule>"
    cat <<XML
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  } > "$d/permissions.xml"
  sign "$d/permissions.xml" "$d/permissions.p7s"
done
chmod 644 "$out"/*.pem "$out"/*.xml "$out"/*.p7s "$out"/*/*.pem "$out"/*/*.xml "$out"/*/*.p7s 2>/dev/null || true
chmod 600 "$out"/ca.key "$out"/*/key.pem
echo "DDS Security for ${hosts[*]} written to $out (CA: $out/ca.pem)"
