//! The template writer and the instruction reader, against PEST++'s own test cases
//! (`model/tests/data/pestpp/`) and each instruction form.

use super::instructions::Instructions;
use super::template::{fit, Template};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn pestpp(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/pestpp/tplins_test_1")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// What PEST++'s instruction file `ins` reads from its output `output`, by observation.
fn read_by_name(ins: &str, output: &str) -> BTreeMap<String, f64> {
    let instructions = Instructions::parse(&pestpp(ins), ins).unwrap();
    let values = instructions.read(&pestpp(output), output).unwrap();
    instructions
        .observations()
        .iter()
        .cloned()
        .zip(values)
        .collect()
}

/// The observation values of a PEST observation file (`name value` per line).
fn obf(text: &str) -> Vec<(String, f64)> {
    text.lines()
        .filter_map(|l| {
            let mut words = l.split_whitespace();
            Some((words.next()?.to_string(), words.next()?.parse().ok()?))
        })
        .collect()
}

/// PEST++'s `out1.dat.ins` on its model output reads what PEST's tools wrote to
/// `out1.dat.obf` (printed to 7 significant digits): markers with blanks inside, commas as
/// secondary markers and as separators, fixed, semi-fixed and non-fixed observations.
#[test]
fn pestpps_instruction_file_reads_what_its_observation_file_holds() {
    let read = read_by_name("out1.dat.ins", "out1_copy.dat");
    let expected = obf(&pestpp("out1.dat.obf"));
    assert_eq!(expected.len(), 20);
    for (name, value) in &expected {
        let got = read[name];
        assert!(
            ((got - value) / value).abs() < 5e-7,
            "{name}: read {got}, PEST {value}"
        );
    }
    // The file's last line reads one more, which the .obf predates.
    assert_eq!(
        read["dummy_obs"],
        "123456789.987654321".parse::<f64>().unwrap()
    );
    assert_eq!(read.len(), expected.len() + 1);
}

/// The same file with some observations read as dummies (`!dum!`, `!DUM!`) reads the others
/// alike.
#[test]
fn dummy_observations_are_read_and_kept_out() {
    let full = Instructions::parse(&pestpp("out1.dat.ins"), "out1.dat.ins").unwrap();
    let dummies = Instructions::parse(&pestpp("out1dum.dat.ins"), "out1dum.dat.ins").unwrap();
    let output = pestpp("out1_copy.dat");
    let all: BTreeMap<String, f64> = full
        .observations()
        .iter()
        .cloned()
        .zip(full.read(&output, "out1.dat").unwrap())
        .collect();
    let some = dummies.read(&output, "out1.dat").unwrap();
    assert!(!dummies
        .observations()
        .iter()
        .any(|o| o == "h01_03" || o == "h01_07"));
    assert_eq!(some.len(), dummies.observations().len());
    for (name, value) in dummies.observations().iter().zip(some) {
        assert_eq!(all[name], value, "{name}");
    }
}

/// PEST++'s `AOC_obs.txt.ins`: a line advance before the first line, a dummy, and
/// secondary markers between numbers, on a table of 11 observations a row.
#[test]
fn pestpps_table_instructions_read_every_row() {
    let read = read_by_name("AOC_obs.txt.ins", "AOC_obs_copy.txt");
    assert_eq!(read.len(), 11 * 9, "11 observations on each of 9 rows");
    // Row "  0.00      5.7103 0.811 ... 3.119 % 0.959 % 12.321 % 8.606 %".
    assert_eq!(read["SUM_MASS0"], 5.7103);
    assert_eq!(read["ES_1mi0"], 3.119);
    assert_eq!(read["PAL_05mi0"], 8.606);
    assert_eq!(read["SUM_MASS5"], 2.3257);
}

/// Each form on a small output: line advances, a primary marker searched from the next
/// line, a secondary marker, whitespace, a tab, fixed and semi-fixed columns, a Fortran `D`
/// exponent, a continued line.
#[test]
fn each_instruction_form_reads_its_number() {
    let output = "header 1 2 3\n\
                  x = 1.5D+02 ; y = -2.25\n\
                  RESULT\n\
                  a    b    7.0e-3   99\n\
                  12345678 0.125\n";
    let ins = "pif @\n\
               l2 @x =@ !x! @y =@ !y!\n\
               @RESULT@\n\
               l1 w w !c! t19 !d!\n\
               & \n\
               l1 [e]1:4 (f)9:12\n";
    let instructions = Instructions::parse(ins, "t.ins").unwrap();
    assert_eq!(instructions.observations(), ["x", "y", "c", "d", "e", "f"]);
    let values = instructions.read(output, "out.txt").unwrap();
    assert_eq!(values, [150.0, -2.25, 7.0e-3, 99.0, 1234.0, 0.125]);
}

/// Mistakes name the file, the line and the column: in the instruction file, and in
/// reading an output with it.
#[test]
fn mistakes_name_the_file_line_and_column() {
    let error = Instructions::parse("pif @\nl1 !a! [b]5\n", "m.ins").unwrap_err();
    assert_eq!((error.line, error.column), (2, 8), "{error}");
    assert!(error.to_string().starts_with("m.ins:2:8: "), "{error}");
    let error = Instructions::parse("pif @\n!a!\n", "m.ins").unwrap_err();
    assert_eq!((error.line, error.column), (2, 1), "{error}");
    assert!(Instructions::parse("pif\n", "m.ins").is_err());
    assert!(Instructions::parse("ptf @\n", "m.ins").is_err());
    let unclosed = Instructions::parse("pif @\n@abc !x!\n", "m.ins").unwrap_err();
    assert!(unclosed.message.contains("not closed"), "{unclosed}");

    let instructions = Instructions::parse("pif @\nl1 @key@ !v!\nl1 !w!\n", "r.ins").unwrap();
    let error = instructions
        .read("no marker here 3\n", "out.txt")
        .unwrap_err();
    assert_eq!((error.line, error.column), (2, 4), "{error}");
    assert!(
        error.message.contains("`key`") && error.message.contains("out.txt"),
        "{error}"
    );
    let error = instructions.read("key 1.0\nnan\n", "out.txt").unwrap_err();
    assert_eq!((error.line, error.column), (3, 4), "{error}");
    assert!(error.message.contains("`nan` is not a number"), "{error}");
    let error = instructions.read("key 1.0\n", "out.txt").unwrap_err();
    assert!(error.message.contains("ends after 1 lines"), "{error}");
}

/// PEST++'s template: every space found with its width, and the file written with each
/// value in its space's width, read back within the precision the width allows.
#[test]
fn pestpps_template_is_written_in_its_spaces() {
    let text = pestpp("hk_Layer_1.ref.tpl");
    let template = Template::parse(&text, "hk_Layer_1.ref.tpl").unwrap();
    let names: Vec<&str> = template.parameters();
    assert_eq!(names.len(), 10, "{names:?}");
    let values: BTreeMap<String, f64> = names
        .iter()
        .enumerate()
        .map(|(k, n)| (n.to_string(), 0.0123456789 * 10f64.powi(k as i32 - 3)))
        .collect();
    let written = template.write(&values).unwrap();
    let body: String = text.split_inclusive('\n').skip(1).collect();
    assert_eq!(written.len(), body.len(), "spaces keep their widths");
    // Each space holds its value, to what its width allows.
    let spaces = body.split('~').collect::<Vec<_>>();
    let mut at = 0;
    for (k, piece) in spaces.iter().enumerate() {
        if k % 2 == 1 {
            let width = piece.chars().count() + 2;
            let name = piece.trim();
            let shown: f64 = written[at..at + width].trim().parse().unwrap();
            let value = values[name];
            let digits = width.saturating_sub(6).max(1) as i32;
            assert!(
                ((shown - value) / value).abs() <= 10f64.powi(1 - digits),
                "{name}: {shown} for {value} in {width}"
            );
            at += width;
        } else {
            at += piece.len();
        }
    }
}

/// A value is written with as many digits as its width holds, a decimal point always, and
/// refused when even one digit does not fit.
#[test]
fn values_fit_their_width_as_closely_as_it_allows() {
    assert_eq!(fit(0.0123456789, 6).unwrap(), ".01235");
    assert_eq!(fit(2.5, 3).unwrap(), "2.5");
    assert_eq!(fit(3.0, 2).unwrap(), "3.");
    assert_eq!(fit(-0.5, 3).unwrap(), "-.5");
    assert_eq!(fit(123456789.0, 7).unwrap(), "1.235E8");
    assert_eq!(fit(1.2345678e-7, 9).unwrap(), "1.2346E-7");
    assert_eq!(
        fit(1.0 / 3.0, 24).unwrap().parse::<f64>().unwrap(),
        1.0 / 3.0
    );
    assert_eq!(fit(123456.0, 3), None);
    assert_eq!(fit(f64::NAN, 10), None);
    for (value, width) in [(6.02214076e23, 8), (-1.5e-300, 9), (42.0, 4), (0.1, 13)] {
        let text = fit(value, width).unwrap();
        assert!(text.len() <= width && text.contains('.'), "{text}");
    }
    let template = Template::parse("ptf #\nk = #k  #\n", "t.tpl").unwrap();
    let error = template
        .write(&BTreeMap::from([("k".to_string(), 1e300)]))
        .unwrap_err();
    assert_eq!((error.line, error.column), (2, 5), "{error}");
    let missing = template.write(&BTreeMap::new()).unwrap_err();
    assert!(missing.message.contains("no value for `k`"), "{missing}");
}

/// PEST++'s control file: its parameters (fixed and log), observations with weights, the
/// command, the files, NOPTMAX, and the sections read by nothing named.
#[test]
fn pestpps_control_file_is_read() {
    use super::control::{ControlFile, Transform};
    let pst = ControlFile::parse(&pestpp("pest.pst"), "pest.pst").unwrap();
    assert_eq!(pst.parameters.len(), 11);
    assert_eq!(pst.parameters[0].name, "stage");
    assert_eq!(pst.parameters[0].transform, Transform::Fixed);
    assert_eq!(pst.parameters[2].transform, Transform::Log);
    assert_eq!(
        pst.parameters[2].initial,
        "2.5000000000111111".parse().unwrap()
    );
    assert_eq!(pst.parameters[1].lower, -5.0e8);
    assert_eq!(pst.observations.len(), 21);
    let weighted: Vec<&str> = pst
        .observations
        .iter()
        .filter(|o| o.weight > 0.0)
        .map(|o| o.name.as_str())
        .collect();
    assert_eq!(weighted, ["h01_04", "h01_06"]);
    assert_eq!(pst.command, "python forward_run.py");
    assert_eq!(pst.templates.len(), 2);
    assert_eq!(
        pst.instructions,
        [("out1.dat.ins".to_string(), "out1.dat".to_string())]
    );
    assert_eq!(pst.noptmax, -1);
    assert_eq!(
        pst.ignored,
        [
            "singular value decomposition",
            "parameter groups",
            "observation groups"
        ]
    );
}

/// PEST's phi of PEST++'s case at its initial values: the templates written with them, the
/// model's output read with the instruction file, Σ (w·(obs − sim))² over the observations:
/// two weighted ones, each 0.5 off with weight 10.
#[test]
fn pestpps_case_has_the_phi_of_its_weighted_residuals() {
    use super::control::ControlFile;
    let pst = ControlFile::parse(&pestpp("pest.pst"), "pest.pst").unwrap();
    let values = pst.model_values(&BTreeMap::new());
    let written: Vec<String> = pst
        .templates
        .iter()
        .map(|(tpl, _)| {
            let template = Template::parse(&pestpp(tpl), tpl).unwrap();
            template.write(&values).unwrap()
        })
        .collect();
    // k_02 starts at 2.5000000000111111 (in a 14-character space); stage at 1.
    assert!(written[0].contains(" 2.500000000011 "), "{}", written[0]);
    assert!(written[1].trim_start().starts_with("1. "), "{}", written[1]);
    let (ins, _) = &pst.instructions[0];
    let simulated: BTreeMap<String, f64> = read_by_name(ins, "out1_copy.dat")
        .into_iter()
        .map(|(k, v)| (k.to_ascii_lowercase(), v))
        .collect();
    let phi = pst.phi(&simulated).unwrap();
    assert!((phi - 50.0).abs() < 1e-12, "{phi}");
    let mut short = simulated.clone();
    short.remove("h01_04");
    assert!(pst.phi(&short).unwrap_err().contains("h01_04"));
}
