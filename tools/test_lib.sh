# Shared by the test scripts tools/test_deb.sh and tools/test_service.sh (sourced, not run).

# make_work_dir [DIR]: $work = DIR (created, made absolute) or, without DIR, a new temporary
# directory; $temporary = 1 for the latter (the caller removes it at exit).
make_work_dir() {
  work="${1:-}"
  temporary=0
  if [[ -z "$work" ]]; then
    work="$(mktemp -d)"
    temporary=1
  fi
  mkdir -p "$work"
  work="$(cd "$work" && pwd)"
}

# skip_or_fail NAME CODE REASON: a test that cannot run here. Under CI=true or
# POISE_REQUIRE_ALL=1 it fails ("NAME: FAILED: ...", exit 1): CI cannot go green by skipping;
# else "NAME: SKIPPED: REASON" and exit CODE.
skip_or_fail() {
  if [[ "${CI:-}" == true || "${POISE_REQUIRE_ALL:-}" == 1 ]]; then
    echo "$1: FAILED: cannot run and skipping is not allowed (CI=true / POISE_REQUIRE_ALL=1): $3" >&2
    exit 1
  fi
  echo "$1: SKIPPED: $3" >&2
  exit "$2"
}
