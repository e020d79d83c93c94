//! `#[derive(Entity)]` for esgm: a plain struct with named fields becomes an entity
//! structure type, with conversions both ways.
//!
//! Generated code names `::esgm_core::…` paths only, so the macro works from any crate
//! that depends on esgm-core (and inside esgm-core, which aliases itself).
//!
//! Attributes:
//! - `#[entity(name = "TypeName")]` on the struct: the registered type name (default:
//!   the struct's identifier).
//! - `#[entity(rename = "attr")]` on a field: the attribute name (default: the field's
//!   identifier).
#![deny(missing_docs)]

use proc_macro::TokenStream;
use quote::quote;
use syn::{Data, DeriveInput, Fields, LitStr, parse_macro_input, spanned::Spanned};

/// Implements `esgm_core::Entity` for a struct with named fields whose types implement
/// `esgm_core::AttributeField`.
#[proc_macro_derive(Entity, attributes(entity))]
pub fn derive_entity(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    expand(&input).unwrap_or_else(|e| e.to_compile_error()).into()
}

fn entity_attr(attrs: &[syn::Attribute], key: &str) -> syn::Result<Option<String>> {
    let mut found = None;
    for attr in attrs.iter().filter(|a| a.path().is_ident("entity")) {
        attr.parse_nested_meta(|meta| {
            if meta.path.is_ident(key) {
                let lit: LitStr = meta.value()?.parse()?;
                found = Some(lit.value());
                Ok(())
            } else {
                Err(meta.error(format!("unknown entity attribute, expected `{key} = \"…\"`")))
            }
        })?;
    }
    Ok(found)
}

fn expand(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new(input.span(), "#[derive(Entity)] needs a struct"));
    };
    let Fields::Named(fields) = &data.fields else {
        return Err(syn::Error::new(input.span(), "#[derive(Entity)] needs named fields"));
    };
    if !input.generics.params.is_empty() {
        return Err(syn::Error::new(
            input.generics.span(),
            "#[derive(Entity)] needs a non-generic struct",
        ));
    }
    let type_name = entity_attr(&input.attrs, "name")?.unwrap_or_else(|| ident.to_string());

    let mut attrs = Vec::new();
    let mut to = Vec::new();
    let mut from = Vec::new();
    for f in &fields.named {
        let Some(fid) = f.ident.as_ref() else { continue };
        let ty = &f.ty;
        let name = entity_attr(&f.attrs, "rename")?.unwrap_or_else(|| fid.to_string());
        attrs.push(quote! {
            ::esgm_core::Attr {
                name: ::std::string::String::from(#name),
                sort: <#ty as ::esgm_core::AttributeField>::SORT,
                element_type: <#ty as ::esgm_core::AttributeField>::element_type()
                    .map(::std::string::String::from),
            }
        });
        to.push(quote! {
            ::esgm_core::AttributeValuePair {
                name: ::std::string::String::from(#name),
                value: ::esgm_core::AttributeField::to_value(&self.#fid),
            }
        });
        from.push(quote! {
            #fid: ::esgm_core::entity::read_field::<#ty>(attributes, #type_name, #name)?
        });
    }

    Ok(quote! {
        impl ::esgm_core::Entity for #ident {
            const TYPE_NAME: &'static str = #type_name;

            fn entity_structure_type() -> ::esgm_core::EntityStructureType {
                ::esgm_core::EntityStructureType {
                    name: ::std::string::String::from(#type_name),
                    attributes: ::std::vec![#(#attrs),*],
                }
            }

            fn to_attributes(&self) -> ::std::vec::Vec<::esgm_core::AttributeValuePair> {
                ::std::vec![#(#to),*]
            }

            fn from_attributes(
                attributes: &[::esgm_core::AttributeValuePair],
            ) -> ::std::result::Result<Self, ::esgm_core::FromEntityError> {
                ::std::result::Result::Ok(Self { #(#from),* })
            }
        }

        /// A typed entity nests as a frame whose element type is its own.
        impl ::esgm_core::AttributeField for #ident {
            const SORT: ::esgm_core::ValueSort = ::esgm_core::ValueSort::EntityFrame;
            fn element_type() -> ::std::option::Option<&'static str> {
                ::std::option::Option::Some(#type_name)
            }
            fn to_value(&self) -> ::esgm_core::Value {
                ::esgm_core::Value::EntityFrame(::std::boxed::Box::new(
                    ::esgm_core::Entity::to_frame(self, #type_name),
                ))
            }
            fn from_value(value: &::esgm_core::Value) -> ::std::option::Option<Self> {
                value.as_frame().and_then(|f| <Self as ::esgm_core::Entity>::from_frame(f).ok())
            }
        }
    })
}
