# Runs `npm ci` in the build tree's copy of web/ (cmake -P web/npm_ci.cmake), so that a failure
# says what the build needs instead of ending with npm's log alone.
#
#   cmake -DNPM=/usr/bin/npm -DDIR=<build>/web -DSTAMP=<file> [-DOMIT_DEV=ON] -P web/npm_ci.cmake
#
# OMIT_DEV: without the devDependencies (puppeteer-core), for a build without tests.
#
# The npm cache lives under DIR (npm-cache/): the build writes nothing outside its tree. The
# lifecycle scripts are not run: nothing the dashboard uses needs them (puppeteer-core drives an
# installed Chromium and downloads no browser).
set(omit)
if(OMIT_DEV)
  set(omit --omit=dev)
endif()
execute_process(
  COMMAND "${NPM}" ci --no-audit --no-fund --ignore-scripts --cache "${DIR}/npm-cache"
          --fetch-retries=2 --fetch-timeout=60000 ${omit}
  WORKING_DIRECTORY "${DIR}"
  RESULT_VARIABLE result)
if(NOT result EQUAL 0)
  message(FATAL_ERROR
          "npm ci failed in ${DIR} (exit ${result}). The dashboard (web/) vendors Chart.js and, "
          "for its browser tests, puppeteer-core from the npm registry at build time, pinned by "
          "web/package-lock.json: the build needs the registry (npm config get registry) to be "
          "reachable. Nothing is fetched at run time.")
endif()
file(TOUCH "${STAMP}")
