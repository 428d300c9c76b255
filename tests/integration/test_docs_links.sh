#!/usr/bin/env bash
# The documentation's links and the sources' citations hold
# (tests/support/docs_check.py `links` and `citations`):
#  - every relative link of README.md and docs/*.md (any page, found by
#    name, so a new page is checked as soon as it exists) names a file
#    inside the repository, and its #anchor a heading of that page;
#  - no file of the repository (git's tracked and not-ignored files, else
#    every file outside build directories) cites a path outside it: the
#    reference notes it was written from, or a machine's own directories;
#    sources cite papers or docs/ pages instead;
#  - every "docs/<page>.md#anchor" and "README.md#<anchor>" a file cites
#    exists;
#  - and the checker catches each kind of mistake (a negative control).
# Ends with "test_docs_links: N passed, N failed" (tests/run.sh sums it).
set -u
name=test_docs_links
source "$(dirname "$0")/../support/shtest.sh"
cd "$root" || exit 1
tool=(python3 "$root/tests/support/docs_check.py")

# count LOG: each PASS line is a pass, each FAIL line a failure.
count() {
  local line
  while IFS= read -r line; do
    case $line in
      PASS*) ok ;;
      FAIL*) bad "${line#FAIL }" ;;
      *) bad "docs_check.py: $line" ;;
    esac
  done <"$1"
}

"${tool[@]}" links "$root" README.md docs/*.md >"$tmp/links.log" 2>&1
count "$tmp/links.log"

if git -C "$root" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  git -C "$root" ls-files -z --cached --others --exclude-standard >"$tmp/files"
else
  find . -type f ! -path './.git/*' ! -path './build*' -printf '%P\0' >"$tmp/files"
fi
# (Binary files are skipped by the checker; it reads text only.)
xargs -0 -r "${tool[@]}" citations "$root" <"$tmp/files" >"$tmp/cite.log" 2>&1
count "$tmp/cite.log"
[ -s "$tmp/cite.log" ] && ok || bad "citations: no file checked"

# ---- negative control: each mistake is reported --------------------------
# ($d: the page names are spelled through it, so that the citation check
# of this file does not read them as citations of pages that do not exist;
# the README anchor below is split by "" for the same reason.)
d=docs
mkdir -p "$tmp/neg/$d"
printf '# Page\n\n## A heading\n' >"$tmp/neg/$d/page.md"
cat >"$tmp/neg/README.md" <<MD
[ok]($d/page.md#a-heading) [missing file]($d/nope.md)
[missing anchor]($d/page.md#no-heading) [outside](../elsewhere.md)
MD
printf '/* see kernel-%s.md 1.2 */\n/* %s/page.md#a-heading, %s/page.md#gone */\n/* README.md#%s */\n' behavior $d $d gone >"$tmp/neg/src.c"
printf '/* (see ../%s/reference/x.md) */\n' shared >"$tmp/neg/other.c"
{
  "${tool[@]}" links "$tmp/neg" "$tmp/neg/README.md"
  "${tool[@]}" citations "$tmp/neg" "$tmp/neg/src.c" "$tmp/neg/other.c"
} >"$tmp/neg.log" 2>&1
for want in "README.md:1: link $d/nope.md: $d/nope.md does not exist" \
  "README.md:2: link $d/page.md#no-heading: no heading #no-heading" \
  "README.md:2: link ../elsewhere.md leaves the repository" \
  "src.c:1: cites a path outside the repository" "src.c:2: cites $d/page.md#gone: no such heading" \
  "src.c:3: cites README.md#""gone: no such heading" \
  "other.c:1: cites a path outside the repository"; do
  if grep '^FAIL' "$tmp/neg.log" | grep -qF "$want"; then ok; else
    bad "docs_check.py did not report '$want': $(tr '\n' ' ' <"$tmp/neg.log" | head -c 600)"
  fi
done
n=$(grep -c '^FAIL' "$tmp/neg.log")
[ "$n" = 7 ] && ok || bad "the negative control has 7 mistakes; docs_check.py reported $n: $(tr '\n' ' ' <"$tmp/neg.log" | head -c 600)"

finish
