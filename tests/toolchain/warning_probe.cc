// Compiled only by the test build.warnings_are_errors_only_when_strict: the
// unused variable below is a deliberate warning (-Wall), which must stay a
// warning in a user's build and become an error in the strict build.
int WarningProbe() {
  int deliberately_unused = 1;
  return 0;
}
