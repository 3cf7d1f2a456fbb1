#!/usr/bin/env bash
# Compiles every Kotlin file under android/ (the library, its Camera2/CameraX glue and the
# sample app) against the real Android 14 framework classes (Robolectric's android-all jar
# from Maven Central) and a small CameraX stub set (android/jvm-test/stubs: Google's Maven is
# not reachable here), then runs the JVM tests (android/jvm-test/src/test: scripted camera
# sequences, and the Android glue under Robolectric) against the real libcampro_jni.so.
#
# Also compiles what `campro convert --format kotlin` prints (target/generated-snippets).
#
# Needs: JDK 17, Maven, cargo. Last line: "kotlin files compiled: N/M" (M = every .kt under
# android/, tests and stubs included). Exits non-zero when anything fails to compile or a
# test fails.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
cd "$root"

# The .so the tests load: the JNI crate alone (no desktop features), as an app builds it,
# plus its test-exports feature, which only adds functions (the core's emulator and desktop
# pipeline for the simulated camera of org.campro.hal).
cargo build --release --locked --lib -p campro-jni --features test-exports
lib="$root/target/release/libcampro_jni.so"
test -f "$lib"

# The statements `campro convert --format kotlin` prints (with known gains and with gains
# read back from a result), wrapped in functions, so that they compile against the real
# framework classes too.
snippets="$here/jvm-test/target/generated-snippets"
rm -rf "$snippets" && mkdir -p "$snippets"
{
  echo "package org.campro.snippets"
  echo "import android.hardware.camera2.CaptureRequest"
  echo "import android.hardware.camera2.CaptureResult"
  echo "import android.hardware.camera2.params.ColorSpaceTransform"
  echo "import android.hardware.camera2.params.RggbChannelVector"
  echo "import android.hardware.camera2.params.TonemapCurve"
  echo "fun withKnownGains(builder: CaptureRequest.Builder) {"
  cargo run -q --release --locked -p campro-cli -- convert campro-omega-0.5 --format kotlin --device-gains 2 1 1 1.5
  echo "}"
  echo "fun withMeteredGains(builder: CaptureRequest.Builder, meteringResult: CaptureResult) {"
  cargo run -q --release --locked -p campro-cli -- convert campro-omega-0.5 --format kotlin
  echo "}"
} > "$snippets/ConvertSnippets.kt"

# The README's Android block (after its Gradle line), as the body of a function whose
# parameters are the names it takes from an app: the entry point a newcomer copies compiles.
{
  echo "package org.campro.snippets"
  echo "import android.content.Context"
  echo "import androidx.lifecycle.LifecycleOwner"
  echo "import org.campro.ProtectionState"
  echo "import org.campro.android.*"
  echo "import java.io.File"
  echo "import java.util.concurrent.Executor"
  echo "fun readmeAndroid(context: Context, lifecycleOwner: LifecycleOwner, mainExecutor: Executor, filesDir: File,"
  echo "    previewView: CamProPreviewView, showNotAvailable: () -> Unit, show: (ProtectionState) -> Unit) {"
  awk '/^## On Android/{a=1} a&&/^```kotlin/{k=1;next} k&&/^```/{exit} k&&!/^implementation\(/{print}' "$root/README.md"
  echo "}"
} > "$snippets/ReadmeSnippet.kt"
test "$(grep -c . "$snippets/ReadmeSnippet.kt")" -gt 12

# Compile (main: library + app + stubs + snippets; test: the tests) and run the tests.
mvn -B -q -f "$here/jvm-test/pom.xml" -Dcampro.jni.dir="$(dirname "$lib")" test
# Surefire's summary for the log (Maven ran quietly).
reports="$here/jvm-test/target/surefire-reports"
python3 - "$reports" <<'PY'
import sys, glob, xml.etree.ElementTree as ET
t = f = e = s = 0
for x in sorted(glob.glob(sys.argv[1] + "/TEST-*.xml")):
    r = ET.parse(x).getroot()
    n, fl, er, sk = (int(r.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
    t += n; f += fl; e += er; s += sk
    print(f"{r.get('name')}: {n} tests, {fl + er} failed")
print(f"Tests run: {t}, Failures: {f}, Errors: {e}, Skipped: {s}")
PY

# The simulated camera's scenarios (org.campro.hal.HalScenariosTest): the table and the count.
hal="$here/jvm-test/target/hal-scenarios.md"
test -s "$hal"
cat "$hal"
echo "hal scenarios: $(grep -c '| yes |$' "$hal")/$(( $(grep -c '^| ' "$hal") - 1 )) held"

# Every .kt under android/ must have become a class file of this build.
total=0; compiled=0
classes="$here/jvm-test/target/classes"; tclasses="$here/jvm-test/target/test-classes"
while IFS= read -r kt; do
  total=$((total + 1))
  # A Kotlin file compiles to FileKt.class and/or the classes it declares: look for any
  # class whose source attribute names this file.
  name="$(basename "$kt")"
  if grep -rlaF --include='*.class' "$name" "$classes" "$tclasses" >/dev/null 2>&1; then
    compiled=$((compiled + 1))
  else
    echo "not compiled: ${kt#$root/}" >&2
  fi
done < <(find "$here" -name '*.kt' -not -path '*/target/*' -not -path '*/build/*' | sort)
echo "kotlin files compiled: $compiled/$total"
test "$compiled" -eq "$total"
