# Issue 24, readers: every reader bounds what it reads before it allocates (/dev/zero as a URDF or
# a state, an endless scene on standard input); the URDF importer refuses what it would drop
# (xacro, misplaced or repeated elements, numbers without separators), names the file and line,
# reads a byte-order mark, and refuses names that cannot round-trip.
. "$(dirname "$0")/common.sh"

printf '{"urdf": "/dev/zero"}\n' > zero_urdf.json
run 1 "$TRELLIS" info zero_urdf.json
err_has "zero_urdf.json: scene: field 'urdf': \"/dev/zero\" cannot be read (looked for /dev/zero): /dev/zero: the URDF file is larger than the limit"
err_has "larger than the limit"
run 1 "$TRELLIS" linearize --state /dev/zero "$CART"
err_has "/dev/zero: the state file is larger than the limit"
status=0
yes '{"frames": [' | "$TRELLIS" info - > out.txt 2> err.txt || status=$?
[ "$status" = 1 ] || fail "endless stdin: exit status $status"
err_has "<stdin>: the scene on standard input is larger than the limit"

# xacro: refused with the command that expands it.
cat > arm.urdf.xacro <<'XML'
<?xml version="1.0"?>
<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="link" params="n"><link name="${n}"/></xacro:macro>
  <link name="base"/>
</robot>
XML
run 1 "$TRELLIS" info arm.urdf.xacro
err_has "arm.urdf.xacro:2: <robot> declares xmlns:xacro: this is a xacro file"
err_has "xacro arm.urdf.xacro > robot.urdf"

# A link inside another element, a second <parent>, numbers run together.
cat > nested.urdf <<'XML'
<robot name="r">
  <link name="a"/>
  <link name="b"/>
  <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
    <link name="c"/>
  </joint>
</robot>
XML
run 1 "$TRELLIS" info nested.urdf
err_has "nested.urdf:5: joint 'j': unexpected element <link> inside <joint>"
sed 's#<link name="c"/>#<origin xyz="1.5.2 0"/>#' nested.urdf > numbers.urdf
run 1 "$TRELLIS" info numbers.urdf
err_has "numbers.urdf:5: joint 'j': <origin> attribute 'xyz': value '1.5.2 0' must be 3 finite numbers"

# A byte-order mark before the XML: read, not called invalid JSON.
printf '\357\273\277' > bom.urdf
sed 's#<link name="c"/>##' nested.urdf >> bom.urdf
run 0 "$TRELLIS" info bom.urdf
out_has "j"

# A name that is not UTF-8: the file, line and element, not a JSON library's exception.
sed 's#name="j"#name="\xe9"#; s#<link name="c"/>##' nested.urdf > latin1.urdf
run 1 "$TRELLIS" info latin1.urdf
err_has "latin1.urdf:4: the file is not valid UTF-8"
grep -q "json.exception" err.txt && fail "a JSON library message: $(cat err.txt)"
# A scene with a configuration pair x / dx: refused at load time, not a CSV that cannot be read.
printf '%s\n' '{"frames": [{"name": "a", "type": "tx", "config": "x", "mass": {"m": 1}},' \
  '{"name": "b", "type": "ty", "config": "dx", "mass": {"m": 1}}]}' > pair.json
run 1 "$TRELLIS" info pair.json
err_has "share the CSV column name 'dx'"
exit 0
