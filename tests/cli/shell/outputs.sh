# Issue 24, lost data: an output through a stream appends to what the shell opened; an output that
# must not be replaced (the command's own input, a read-only file, a dangling link) is refused and
# left as it was.
. "$(dirname "$0")/common.sh"

# --out /dev/stdout >> app.log: the old lines stay, the CSV and the summary follow.
echo "old log line" > app.log
status=0
"$TRELLIS" gains "$CART" --trajectory "$UPRIGHT" --out /dev/stdout >> app.log 2> err.txt || status=$?
[ "$status" = 0 ] || fail "gains --out /dev/stdout >> app.log: exit status $status: $(cat err.txt)"
[ "$(head -n 1 app.log)" = "old log line" ] || fail "app.log lost its first line: $(head -n 3 app.log)"
grep -q "^# trellis gain schedule" app.log || fail "app.log lacks the gains CSV"
grep -q "^wrote /dev/stdout: " app.log || fail "app.log lacks the summary"
lines_before=$(wc -l < app.log)
# '-' is standard output too; with `>` the CSV and the summary both arrive.
"$TRELLIS" gains "$CART" --trajectory "$UPRIGHT" --out - > stdout.txt 2> err.txt || fail "--out - failed: $(cat err.txt)"
grep -q "^# trellis gain schedule" stdout.txt || fail "--out -: no CSV on stdout"
[ "$(wc -l < stdout.txt)" -gt 3 ] || fail "--out -: too short"
# The summary follows the CSV (buffered text is flushed in order).
csv_line=$(grep -n "^# trellis gain schedule" stdout.txt | cut -d: -f1)
summary_line=$(grep -n "^wrote -: " stdout.txt | cut -d: -f1)
[ -n "$summary_line" ] && [ "$summary_line" -gt "$csv_line" ] || fail "--out -: the summary is not after the CSV"
rm -f stdout.txt
[ "$lines_before" -gt 3 ] || fail "app.log too short"

# --out naming the command's own input: refused (usage error), the input intact.
cp "$UPRIGHT" ref.csv
ln -s ref.csv alias.csv
run 2 "$TRELLIS" gains "$CART" --trajectory ref.csv --out ref.csv
err_has "gains: --out 'ref.csv' is the --trajectory input 'ref.csv'; writing it would destroy the input"
run 2 "$TRELLIS" gains "$CART" --trajectory ref.csv --out alias.csv
err_has "is the --trajectory input 'ref.csv'"
cmp -s ref.csv "$UPRIGHT" || fail "the reference trajectory was changed"
cp "$CART" scene.json
run 2 "$TRELLIS" gains scene.json --trajectory ref.csv --out scene.json
err_has "is the scene input 'scene.json'"
cmp -s scene.json "$CART" || fail "the scene was changed"

# A read-only file is refused and keeps its text.
echo keep > ro.csv
chmod 0444 ro.csv
run 1 "$TRELLIS" gains "$CART" --trajectory ref.csv --out ro.csv
err_has "ro.csv: is read-only (mode 0444); trellis does not replace a write-protected file"
[ "$(cat ro.csv)" = keep ] || fail "ro.csv was replaced"
[ -s out.txt ] && fail "stdout not empty after a failure"

# A dangling link is refused; no file appears where it points.
ln -s missing/target.csv dangling.csv
run 1 "$TRELLIS" gains "$CART" --trajectory ref.csv --out dangling.csv
err_has "dangling.csv: is a symbolic link to 'missing/target.csv', which cannot be resolved"
[ -L dangling.csv ] || fail "the link was replaced"
[ -e missing ] && fail "a directory or file was created through the link"
only_files app.log ref.csv alias.csv scene.json ro.csv dangling.csv
exit 0
