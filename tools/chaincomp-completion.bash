# bash completion for chaincomp; generated from its parser by
#   python -m chaincomp.cli.completion > tools/chaincomp-completion.bash
# (tests/python/cli/test_cli_consistency.py checks that it is up to date). Source it, or copy it
# to /etc/bash_completion.d/chaincomp.
_chaincomp() {
    local cur="${COMP_WORDS[COMP_CWORD]}" prev="${COMP_WORDS[COMP_CWORD-1]}" verb="" words i
    COMPREPLY=()
    for ((i = 1; i < COMP_CWORD; i++)); do
        case "${COMP_WORDS[i]}" in -*) ;; *) verb="${COMP_WORDS[i]}"; break;; esac
    done
    if [[ -z $verb ]]; then
        words='derive eval generate testvectors protocol identify simulate-measurements simulate-log replay plot check report budget simulate-calibration build lint iso230-2 laser-to-params status import-urdf export-urdf import-ur-calibration ballbar export thermal simulate-thermal probe -h --help --version'
    else
        case "$verb" in
        derive)
          case "$prev" in
            --format) words='text latex json';;
            *) words='-h --help --order --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        eval)
          case "$prev" in
            --format) words='text json';;
            --units) words='people internal';;
            *) words='-h --help --params --set --format --json --units'; [[ $cur == -* ]] || return 0;;
          esac;;
        generate)
          case "$prev" in
            *) words='-h --help --order -o --output --registry --registry-only'; [[ $cur == -* ]] || return 0;;
          esac;;
        testvectors)
          case "$prev" in
            *) words='-h --help --count --seed -o --output'; [[ $cur == -* ]] || return 0;;
          esac;;
        protocol)
          case "$prev" in
            --index) words='min-sv o1';;
            --format) words='text json';;
            *) words='-h --help --angles --assume-zero --measure --prefer --set --order --poses --index --pool --seed -o --output --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        identify)
          case "$prev" in
            --units) words='people internal';;
            --format) words='text json';;
            *) words='-h --help --assume-zero --hold --sigma --minimal --prefer --vary --smooth -o --output --strict --loss --report --units --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        simulate-measurements)
          case "$prev" in
            *) words='-h --help --params --setups --set-ups --set --noise --angle-noise --measure --seed -o --output'; [[ $cur == -* ]] || return 0;;
          esac;;
        simulate-log)
          case "$prev" in
            *) words='-h --help -o --output --rate --seconds --channel --start-utime'; [[ $cur == -* ]] || return 0;;
          esac;;
        replay)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --model --params --config --thermal -o --output --csv --channel --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        plot)
          case "$prev" in
            --view) words='map surface volume';;
            --component) words='dx dy dz dkx dky dkz norm';;
            --order) words='1 2 exact 2-1 exact-1 exact-2';;
            --units) words='people internal';;
            *) words='-h --help --params --set --view --component --over --range --range2 --grid --order --units --replay --table --error -o --output --html'; [[ $cur == -* ]] || return 0;;
          esac;;
        check)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --order --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        report)
          case "$prev" in
            --format) words='markdown latex';;
            *) words='-h --help --order -o --output --format --protocol --assume-zero'; [[ $cur == -* ]] || return 0;;
          esac;;
        budget)
          case "$prev" in
            --order) words='1 2 exact';;
            --format) words='text json';;
            --units) words='people internal';;
            --component) words='dx dy dz dkx dky dkz wx wy wz';;
            *) words='-h --help --params --set --tolerances --over --grid --order --samples --seed --format --json --units --top --plot --map --component'; [[ $cur == -* ]] || return 0;;
          esac;;
        simulate-calibration)
          case "$prev" in
            --interpolation) words='linear monotone_cubic';;
            --outside) words='hold reject';;
            *) words='-h --help -o --output --knots --seed --params --interpolation --outside'; [[ $cur == -* ]] || return 0;;
          esac;;
        build)
          case "$prev" in
            *) words='-h --help -o --output --linuxcnc --params --name --install'; [[ $cur == -* ]] || return 0;;
          esac;;
        lint)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --strict --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        iso230-2)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --columns --column-units --format --json --plot'; [[ $cur == -* ]] || return 0;;
          esac;;
        laser-to-params)
          case "$prev" in
            --direction) words='mean up down';;
            --interpolation) words='linear monotone_cubic';;
            --outside) words='hold reject';;
            *) words='-h --help --columns --column-units --error --axis --direction -o --output --merge --interpolation --outside'; [[ $cur == -* ]] || return 0;;
          esac;;
        status)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --url --once --format --json --timeout --refresh'; [[ $cur == -* ]] || return 0;;
          esac;;
        import-urdf)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --base --tip --errors --tool-point --tool-direction --tool-reference --name -o --output --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        export-urdf)
          case "$prev" in
            --as) words='urdf ur-calibration';;
            --format) words='text json';;
            *) words='-h --help --base --tip --params --as -o --output --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        import-ur-calibration)
          case "$prev" in
            --format) words='text json';;
            *) words='-h --help --base --tip -o --output --format --json'; [[ $cur == -* ]] || return 0;;
          esac;;
        ballbar)
          case "$prev" in
            --plane) words='XY YZ ZX';;
            --format) words='text json';;
            *) words='-h --help --params --set --plane --radius --centre --center --axes --points --feed --fit --degree --assume-zero --prefer --format --json --plot -o --output'; [[ $cur == -* ]] || return 0;;
          esac;;
        export)
          case "$prev" in
            --controller) words='linuxcnc-comp linuxcnc-matrixkins klipper marlin rrf isg-volcomp';;
            --format) words='text json';;
            --comp-file-type) words='0 1';;
            *) words='-h --help --params --set --controller --format --json -o --output --grid --entries --workpiece-axes --iso-axes --comp-file-type --joints --mean-reversal --no-breakdown'; [[ $cur == -* ]] || return 0;;
          esac;;
        thermal)
          case "$prev" in
            thermal) words='fit check stream';;
            --format) words='text json';;
            --controller) words='siemens isg';;
            *) words='-h --help -o --output --errors --sensors --max-sensors --min-improvement --max-uncertainty --no-lag --reference --drift --check --format --json --controller --reference-position'; [[ $cur == -* ]] || return 0;;
          esac;;
        simulate-thermal)
          case "$prev" in
            *) words='-h --help --truth -o --output --cycle --rate --temperature-noise --drift-noise --hall --sensor-lags --seed'; [[ $cur == -* ]] || return 0;;
          esac;;
        probe)
          case "$prev" in
            probe) words='plan fit simulate';;
            --per-axis) words='2 3 4 5 6 7 8 9 10 11 12';;
            --format) words='text json';;
            *) words='-h --help --sphere --radius --stylus --positions --per-axis --backlash-step --clearance --feed --log-name --gcode --csv --hold --assume-zero --format --json --plan --radius-tolerance -o --output --report --params --noise --backlash --seed'; [[ $cur == -* ]] || return 0;;
          esac;;
        *) return 0;;
        esac
    fi
    COMPREPLY=($(compgen -W "$words" -- "$cur"))
}
# -o default: file names where no word fits (machine files, params, outputs)
complete -o default -F _chaincomp chaincomp
